"""CoCo mixed-reality haptics: proxy-based haptic rendering of implicit surfaces and point clouds."""
