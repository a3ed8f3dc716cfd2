"""CoCo mixed-reality display: the OpenGL 3.3 GLManager and the peers it renders."""
