"""Start the Baxter teleoperation replay from a ROS 2 launch file.

    ros2 launch coco_ros baxter_teleop_replay.launch.py [bag:=out/baxter_session] [rate:=1.0] [display:=false]

The launcher is an ordinary node: launch_ros starts it with the application as its first argument
(an installed application is found by name: coco_core.applications), the node's name and namespace
as ``-r __node:=`` / ``-r __ns:=``, and the parameters in a params file. Every ``<arg>`` of the
application is a parameter of the node (coco_ros.parameters), so the launch arguments below reach
the application through ``parameters``; ``name:=value`` words in ``arguments`` would win over them.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription([
        DeclareLaunchArgument("bag", default_value="out/baxter_session",
                              description="bag folder written by baxter-session (or baxter-import)"),
        DeclareLaunchArgument("rate", default_value="1.0", description="replay speed factor (1: real time)"),
        DeclareLaunchArgument("display", default_value="true",
                              description="render the augmented teleoperation view and record it"),
        Node(
            package="coco_ros",
            executable="launcher",
            name="baxter_teleop",
            namespace="coco",
            arguments=["baxter_teleop_replay", "--profile", "5"],
            parameters=[{
                "bag": LaunchConfiguration("bag"),
                "rate": LaunchConfiguration("rate"),
                "display": LaunchConfiguration("display"),
                "output": "out/teleop_launch",
            }],
            output="screen",
        ),
    ])
