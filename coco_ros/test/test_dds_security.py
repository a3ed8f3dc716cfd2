"""What the ROS 2 wheels allow of DDS Security (SROS 2): docs/hosts.md says that their Fast DDS is
built without its security plugins, so that the hosts of an application authenticate each other
with the application's key alone. This checks it: the day a wheel brings the plugins, this test
fails and the docs must say how to use them. Domain 169, localhost only."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

NODE = """
import rclpy
rclpy.init()
try:
    rclpy.create_node("coco_secure")
except Exception as error:
    print(error)
else:
    print("created")
"""


def test_the_wheels_fast_dds_has_no_dds_security(tmp_path: Path) -> None:
    (tmp_path / "enclaves" / "coco").mkdir(parents=True)
    env = {**os.environ, "ROS_DOMAIN_ID": "169", "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "ROS_SECURITY_KEYSTORE": str(tmp_path), "ROS_SECURITY_ENABLE": "true", "ROS_SECURITY_STRATEGY": "Enforce",
           "ROS_SECURITY_ENCLAVE_OVERRIDE": "/coco"}
    done = subprocess.run([sys.executable, "-c", NODE], env=env, capture_output=True, text=True, timeout=60)
    assert "This Fast DDS version doesn't have the security libraries" in done.stdout + done.stderr, done
