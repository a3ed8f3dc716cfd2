"""Fast DDS shared-memory segments that a killed process left in ``/dev/shm``.

Every process with an rclpy node (the ROS launcher, each of its children) is a Fast DDS participant
with a shared-memory segment of its own: ``fastrtps_<16 hex digits>`` with its lock file
``fastrtps_<16 hex digits>_el``, whose ``flock`` the participant holds while it lives. A process
that ends normally removes both; one killed with ``kill -9`` cannot, and Fast DDS leaves the pair
for ever (about 0.5 MB each). Since the kernel drops a dead process's locks, a lock file that a
non-blocking ``flock`` can take has no living owner, which is how ``fastdds shm clean`` tells too.

The ROS launcher removes such abandoned pairs (:func:`remove_abandoned`) before its own node starts,
which cleans what a killed launcher left, and after its children ended, which cleans what a child
killed during the launch left. A pair younger than :data:`GRACE` is left alone: a participant
creates its lock file an instant before it takes the lock. The port segments
(``fastrtps_port<N>`` and their ``sem.fastrtps_port<N>_mutex``) are shared by every participant of a
domain on the machine, and Fast DDS takes over or rebuilds them itself, so the launcher leaves them.

Not always, though: a port whose listener was killed can be left with its segment but without the
lock file that says nobody listens, and every participant that later takes that port hangs while it
is created (``rclpy.create_node`` never returned, seen on a machine where tests kill ROS processes).
:func:`remove_abandoned_ports` removes such ports, as ``fastdds shm clean`` does: the test command
runs it before the suites (``scripts/run_tests.sh``), when no ROS process of the run is alive.
"""

from __future__ import annotations

import fcntl
import os
import re
import time
from pathlib import Path

SHM_DIR = Path("/dev/shm")
LOCK_SUFFIX = "_el"
GRACE = 5.0
"""Seconds a lock file must have existed before its pair may be removed."""
_PARTICIPANT = re.compile(r"fastrtps_[0-9a-f]{16}")
_PORT = re.compile(r"fastrtps_port[0-9]+")


def remove_abandoned(grace: float = GRACE, folder: Path = SHM_DIR) -> list[str]:
    """Remove every participant segment pair in ``folder`` whose lock nobody holds and whose lock file
    is older than ``grace`` seconds; the names removed. A pair that cannot be opened or removed (another
    user's, in the sticky ``/dev/shm``) is left as it is."""
    removed = []
    now = time.time()
    for lock_file in sorted(folder.glob(f"fastrtps_*{LOCK_SUFFIX}")):
        name = lock_file.name[: -len(LOCK_SUFFIX)]
        if not _PARTICIPANT.fullmatch(name):
            continue
        try:
            if now - lock_file.stat().st_mtime < grace:
                continue
        except OSError:
            continue
        if not _unheld(lock_file):  # held: its participant lives
            continue
        try:
            (folder / name).unlink(missing_ok=True)
            lock_file.unlink(missing_ok=True)
        except OSError:
            continue
        removed.append(name)
    return removed


def remove_abandoned_ports(grace: float = GRACE, folder: Path = SHM_DIR) -> list[str]:
    """Remove every port segment in ``folder`` older than ``grace`` seconds whose lock file is missing
    or held by nobody, with its lock file and its semaphore (see the module docstring); the names."""
    removed = []
    now = time.time()
    for segment in sorted(folder.glob("fastrtps_port*")):
        if not _PORT.fullmatch(segment.name):
            continue
        try:
            if now - segment.stat().st_mtime < grace:
                continue
        except OSError:
            continue
        lock_file = folder / f"{segment.name}{LOCK_SUFFIX}"
        if lock_file.exists() and not _unheld(lock_file):
            continue
        try:
            for path in (segment, lock_file, folder / f"sem.{segment.name}_mutex"):
                path.unlink(missing_ok=True)
        except OSError:
            continue
        removed.append(segment.name)
    return removed


def _unheld(lock_file: Path) -> bool:
    """Whether nobody holds ``lock_file``'s flock (its holder died, or never took it)."""
    try:
        descriptor = os.open(lock_file, os.O_RDONLY | os.O_CLOEXEC)
    except OSError:
        return False
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except OSError:
        return False
    finally:
        os.close(descriptor)


if __name__ == "__main__":
    for name in remove_abandoned() + remove_abandoned_ports():
        print(f"removed abandoned Fast DDS segment {name}")
