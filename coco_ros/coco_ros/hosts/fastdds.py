"""Fast DDS's reliability timing for the connections between hosts.

Fast DDS repairs a lost sample of a reliable connection when its reader answers the writer's
heartbeat, sent every 3 s by default: over a link that loses packets, a connection between hosts
stalled for seconds and lost the rest of its samples at the stop (``share/coco_ros/fastdds/
hosts_profile.xml`` has the measurement). rclpy's QoS cannot set that period; a Fast DDS XML profile
can, as the default of every writer and reader of the process. Fast DDS reads its profiles once,
when the process makes its first participant, so a launch with hosts names the profile before any
node exists (:func:`use_hosts_profile`); a profile the user set (``FASTRTPS_DEFAULT_PROFILES_FILE``)
is left as it is.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

log = logging.getLogger("coco.hosts")

VARIABLE = "FASTRTPS_DEFAULT_PROFILES_FILE"


def hosts_profile() -> Path:
    """The installed profile (``share/coco_ros/fastdds/hosts_profile.xml``)."""
    try:
        return Path(get_package_share_directory("coco_ros")) / "fastdds" / "hosts_profile.xml"
    except PackageNotFoundError:  # run from the source tree
        return Path(__file__).resolve().parents[2] / "fastdds" / "hosts_profile.xml"


def use_hosts_profile() -> None:
    """Have this process's participants (and its child processes', which inherit the environment)
    use :func:`hosts_profile`, unless the user chose a profile."""
    if os.environ.get(VARIABLE):
        log.info("%s=%s: the connections between hosts use that Fast DDS profile, not %s", VARIABLE,
                 os.environ[VARIABLE], hosts_profile())
        return
    os.environ[VARIABLE] = str(hosts_profile())
