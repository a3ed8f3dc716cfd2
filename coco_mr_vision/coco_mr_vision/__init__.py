"""CoCo mixed-reality vision: image types, camera readers, marker tracking and streaming."""
