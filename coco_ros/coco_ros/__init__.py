"""CoCo for ROS 2: hosts CoCo applications inside an rclpy node.

The launcher node, the ROSInterface topic<->port bridges and bag replay live here, so that
``coco_core`` stays importable without ROS.
"""
