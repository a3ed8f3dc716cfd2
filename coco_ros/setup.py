import os
from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "coco_ros"
HERE = Path(__file__).resolve().parent


def installed_tree(source: str, target: str) -> list[tuple[str, list[str]]]:
    """data_files entries installing every file under ``source`` (relative to this package) into
    share/<package>/``target``, folders kept: the workspace's applications (config/, with their
    meshes and CSVs) and launch files, found by name from any folder (coco_core.applications)."""
    root = (HERE / source).resolve()
    entries: dict[str, list[str]] = {}
    for path in sorted(root.rglob("*")):
        if path.is_file():
            folder = Path("share", PACKAGE, target, path.parent.relative_to(root))
            entries.setdefault(str(folder), []).append(os.path.relpath(path, HERE))
    return sorted(entries.items())


setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        # Listed in colcon.pkg: puts lib/<pkg> (the console scripts, where `ros2 run` looks) on PATH.
        (f"share/{PACKAGE}/hook", ["hook/scripts_path.dsv", "hook/scripts_path.sh"]),
        *installed_tree("../config", "config"),
        *installed_tree("launch", "launch"),
        *installed_tree("fastdds", "fastdds"),
    ],
    # The launcher is a plain script, not a console-script entry point: see scripts/launcher.
    scripts=["scripts/launcher"],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="CoCo for ROS 2 developers",
    maintainer_email="coco-ros2@example.org",
    description="CoCo for ROS 2: the rclpy launcher node, ROSInterface bridges and bag replay.",
    license="MIT",
    tests_require=["pytest"],
    entry_points={
        "coco.value_types": [
            # What may cross between hosts (coco_core.wire): the decoder of another process
            # loads a type by its name from here, and from nowhere else.
            "coco_ros.convert.joints.JointStateSample = coco_ros.convert.joints:JointStateSample",
            "coco_ros.convert.stamps.RosTime = coco_ros.convert.stamps:RosTime",
            "coco_ros.hosts.sample.Frame = coco_ros.hosts.sample:Frame",
        ],
        "console_scripts": [
            "baxter-import = coco_ros.baxter.importer:main",
            "baxter-session = coco_ros.baxter.session:main",
            "palpation-session = coco_ros.palpation.session:main",
            "coco-replay = coco_ros.replay.cli:main",
        ],
        "coco.host_transports": [
            "dds = coco_ros.hosts.transport:DdsTransport",
        ],
        "coco.components": [
            "BagReplay = coco_ros.replay.component:BagReplay",
            "BagRecorder = coco_ros.replay.recorder:BagRecorder",
            "ROSInterface = coco_ros.interface.component:ROSInterface",
            "TFBridge = coco_ros.tf.bridge:TFBridge",
            "RobotDescription = coco_ros.tf.description:RobotDescription",
            "EndEffectorDistance = coco_ros.teleop.distance:EndEffectorDistance",
            "TeleopSummary = coco_ros.teleop.summary:TeleopSummary",
            "PalpationSummary = coco_ros.palpation.summary:PalpationSummary",
            "ROSHapticDevice = coco_ros.haptics.device:ROSHapticDevice",
            "BagRgbdPeer = coco_ros.vision.rgbd_bag:BagRgbdPeer",
            "TopicRgbdPeer = coco_ros.vision.rgbd_topics:TopicRgbdPeer",
        ],
    },
)
