"""Haptic devices over ROS: a device's ROS driver as a CoCo haptic device."""
