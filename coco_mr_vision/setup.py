from setuptools import find_packages, setup

PACKAGE = "coco_mr_vision"

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
            "coco_mr_vision.image.CameraIntrinsics = coco_mr_vision.image:CameraIntrinsics",
            "coco_mr_vision.image.Image = coco_mr_vision.image:Image",
            "coco_mr_vision.image.ImageFormat = coco_mr_vision.image:ImageFormat",
            "coco_mr_vision.marker_tracker.MarkerDetections = coco_mr_vision.marker_tracker:MarkerDetections",
            "coco_mr_vision.mesh.MeshInfo = coco_mr_vision.mesh:MeshInfo",
            "coco_mr_vision.mesh.MeshLayout = coco_mr_vision.mesh:MeshLayout",
            "coco_mr_vision.pointcloud.PointCloud = coco_mr_vision.pointcloud:PointCloud",
            "coco_mr_vision.rgbd.RGBDFrame = coco_mr_vision.rgbd:RGBDFrame",
        ],
        "coco.components": [
            "ImageConverter = coco_mr_vision.converter:ImageConverter",
            "CameraReader = coco_mr_vision.camera_reader:CameraReader",
            "RgbdCameraReader = coco_mr_vision.rgbd_reader:RgbdCameraReader",
            "TumRgbdPeer = coco_mr_vision.rgbd_peers:TumRgbdPeer",
            "RedwoodRgbdPeer = coco_mr_vision.rgbd_peers:RedwoodRgbdPeer",
            "RealSenseRgbdPeer = coco_mr_vision.realsense_peer:RealSenseRgbdPeer",
            "MarkerTracker = coco_mr_vision.marker_tracker:MarkerTracker",
            "MarkerRegistration = coco_mr_vision.marker_registration:MarkerRegistration",
            "TouchRegistration = coco_mr_vision.touch_registration:TouchRegistration",
            "SimulatedCamera = coco_mr_vision.simulated_camera:SimulatedCamera",
            "MeshReconstructor = coco_mr_vision.mesh_reconstructor:MeshReconstructor",
            "StreamingServer = coco_mr_vision.streaming:StreamingServer",
            "StreamingReceiver = coco_mr_vision.streaming:StreamingReceiver",
        ],
    },
    zip_safe=True,
    maintainer="CoCo for ROS 2 developers",
    maintainer_email="coco-ros2@example.org",
    description="CoCo mixed-reality vision: image types, camera readers, marker tracking.",
    license="MIT",
    tests_require=["pytest"],
)
