from setuptools import find_packages, setup

PACKAGE = "coco_mr_haptics"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
    ],
    install_requires=["setuptools"],
    entry_points={
        "coco.value_types": [
            # What may cross between hosts (coco_core.wire): the decoder of another process
            # loads a type by its name from here, and from nowhere else.
            "coco_mr_haptics.types.HapticDeviceState = coco_mr_haptics.types:HapticDeviceState",
            "coco_mr_haptics.types.HapticForce = coco_mr_haptics.types:HapticForce",
            "coco_mr_haptics.types.HapticSample = coco_mr_haptics.types:HapticSample",
        ],
        "console_scripts": ["haptic-plot = coco_mr_haptics.plot:main"],
        "coco.components": [
            "HapticRenderer = coco_mr_haptics.renderer:HapticRenderer",
            "HapticImplicitSurf = coco_mr_haptics.implicit_surf:HapticImplicitSurf",
            "SimulatedDevice = coco_mr_haptics.simulated_device:SimulatedDevice",
            "HapticRecorder = coco_mr_haptics.recorder:HapticRecorder",
            "KDTreeBuilder = coco_mr_haptics.cloud:KDTreeBuilder",
            "HapticCloud = coco_mr_haptics.cloud:HapticCloud",
        ],
    },
    zip_safe=True,
    maintainer="CoCo for ROS 2 developers",
    maintainer_email="coco-ros2@example.org",
    description="CoCo mixed-reality haptics: proxy-based haptic rendering and devices.",
    license="MIT",
    tests_require=["pytest"],
)
