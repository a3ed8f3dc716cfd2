"""Every package's package.xml declares what its code imports (issue: a ROS user installs a package
with rosdep from its package.xml; an undeclared import fails only when that code path runs).

Each third-party module a package's code imports (read with ``ast``, the standard library and the
workspace's own packages left out) must be declared: by its rosdep key as an ``<exec_depend>``, or,
where no rosdep key exists, by its pip name in the package.xml's comment."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("coco_core", "coco_ros", "coco_mr_display", "coco_mr_haptics", "coco_mr_vision")
DECLARED_AS = {
    "numpy": "<exec_depend>python3-numpy</exec_depend>", "cv2": "<exec_depend>python3-opencv</exec_depend>",
    "yaml": "<exec_depend>python3-yaml</exec_depend>", "zmq": "<exec_depend>python3-zmq</exec_depend>",
    "zstandard": "<exec_depend>python3-zstandard</exec_depend>", "lz4": "<exec_depend>python3-lz4</exec_depend>",
    "tqdm": "<exec_depend>python3-tqdm</exec_depend>", "scipy": "<exec_depend>python3-scipy</exec_depend>",
    "numba": "<exec_depend>python3-numba</exec_depend>", "matplotlib": "<exec_depend>python3-matplotlib</exec_depend>",
    "PIL": "<exec_depend>python3-pil</exec_depend>", "pinocchio": "<exec_depend>pinocchio</exec_depend>",
    "msgpack": "<exec_depend>python3-msgpack</exec_depend>",
    "ament_index_python": "<exec_depend>ament_index_python</exec_depend>",
    "mcap": '"mcap"', "rosbags": '"rosbags"', "moderngl": '"moderngl"', "glfw": '"glfw"',
    "trimesh": '"trimesh"', "fast_simplification": '"fast-simplification"',
    "pyrealsense2": '"pyrealsense2"',
}
"""How package.xml declares each third-party module; a ROS message package is declared by its own name."""
WORKSPACE_PACKAGES = {*PACKAGES, "tf2_msgs", "coco_interfaces"}


def imported_modules(package: str) -> set[str]:
    found: set[str] = set()
    for path in (ROOT / package / package).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                found.update(alias.name.split(".")[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                found.add(node.module.split(".")[0])
    return {name for name in found if name not in sys.stdlib_module_names and name != "__future__"}


@pytest.mark.parametrize("package", PACKAGES)
def test_package_xml_declares_every_third_party_import(package: str) -> None:
    manifest = (ROOT / package / "package.xml").read_text()
    missing = []
    for module in sorted(imported_modules(package)):
        if module in WORKSPACE_PACKAGES and module != package:
            declared = f"<exec_depend>{module}</exec_depend>" in manifest
        elif module == package:
            continue
        else:
            declared = DECLARED_AS.get(module, f"<exec_depend>{module}</exec_depend>") in manifest
        if not declared:
            missing.append(module)
    assert not missing, f"{package}/package.xml does not declare {missing}"
