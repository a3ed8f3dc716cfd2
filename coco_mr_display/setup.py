from setuptools import find_packages, setup

PACKAGE = "coco_mr_display"

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
            "coco_mr_display.mesh.MeshPart = coco_mr_display.mesh:MeshPart",
        ],
        "coco.components": [
            "GLManager = coco_mr_display.manager:GLManager",
            "GLCameraManager = coco_mr_display.camera:GLCameraManager",
            "FPSCamera = coco_mr_display.controllers:FPSCamera",
            "ArcBallCamera = coco_mr_display.controllers:ArcBallCamera",
            "FrameWriter = coco_mr_display.frame_writer:FrameWriter",
            "GLImage = coco_mr_display.image:GLImage",
            "GLRGBDImage = coco_mr_display.rgbd:GLRGBDImage",
            "GLEntity = coco_mr_display.entity:GLEntity",
            "UpdateColor = coco_mr_display.update_color:UpdateColor",
            "UpdateVector = coco_mr_display.update_vector:UpdateVector",
            "GLUrdf = coco_mr_display.urdf:GLUrdf",
        ],
    },
    zip_safe=True,
    maintainer="CoCo for ROS 2 developers",
    maintainer_email="coco-ros2@example.org",
    description="CoCo mixed-reality display: OpenGL 3.3 GLManager and its peers.",
    license="MIT",
    tests_require=["pytest"],
)
