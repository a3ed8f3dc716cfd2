from setuptools import find_packages, setup

PACKAGE = "coco_core"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    package_data={"coco_core.transforms": ["web/*.html", "web/*.js", "web/*.css"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        # Listed in colcon.pkg: puts lib/<pkg> (the console scripts, where `ros2 run` looks) on PATH.
        (f"share/{PACKAGE}/hook", ["hook/scripts_path.dsv", "hook/scripts_path.sh"]),
    ],
    # coco-launch is a plain script, not a console-script entry point: see scripts/coco-launch.
    scripts=["scripts/coco-launch"],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="CoCo for ROS 2 developers",
    maintainer_email="coco-ros2@example.org",
    description="CoCo runtime: components, ports, activities, XML applications; importable without ROS.",
    license="MIT",
    tests_require=["pytest"],
    entry_points={
        'coco.value_types': [
            # What may cross between hosts (coco_core.wire): the decoder of another process
            # loads a type by its name from here, and from nowhere else.
            'coco_core.hosts.messages.ClockRequest = coco_core.hosts.messages:ClockRequest',
            'coco_core.hosts.messages.Heartbeat = coco_core.hosts.messages:Heartbeat',
            'coco_core.hosts.messages.Stage = coco_core.hosts.messages:Stage',
            'coco_core.messages.Call = coco_core.messages:Call',
            'coco_core.messages.Damage = coco_core.messages:Damage',
            'coco_core.messages.Outcome = coco_core.messages:Outcome',
            'coco_core.messages.Result = coco_core.messages:Result',
            'coco_core.stamps.Stamped = coco_core.stamps:Stamped',
            'coco_core.stamps.UserStamps = coco_core.stamps:UserStamps',
            'coco_core.transforms.samples.FramePose = coco_core.transforms.samples:FramePose',
            'coco_core.transforms.samples.JointSample = coco_core.transforms.samples:JointSample',
            'coco_core.transforms.samples.TransformSample = coco_core.transforms.samples:TransformSample',
        ],
        'console_scripts': [
            'coco-keygen = coco_core.hosts.key:keygen',
        ],
        'coco.components': [
            'SignalGenerator = coco_core.demo.signal_generator:SignalGenerator',
            'MovingAverage = coco_core.demo.moving_average:MovingAverage',
            'CsvRecorder = coco_core.demo.csv_recorder:CsvRecorder',
            'RangeMonitor = coco_core.demo.range_monitor:RangeMonitor',
            'Supervisor = coco_core.demo.supervisor:Supervisor',
            'TransformationInterface = coco_core.transforms.interface:TransformationInterface',
            'JointSequence = coco_core.transforms.joint_sequence:JointSequence',
            'Relay = coco_core.relay:Relay',
            'CostlyProducer = coco_core.demo.coupling:CostlyProducer',
            'CostlyConsumer = coco_core.demo.coupling:CostlyConsumer',
            'BoxEmitter = coco_core.demo.routing:BoxEmitter',
            'StampRecorder = coco_core.demo.routing:StampRecorder',
        ],
    },
)
