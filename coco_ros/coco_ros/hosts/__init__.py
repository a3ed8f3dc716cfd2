"""Connections between hosts over DDS (rclpy): the data path of an application spread over several
hosts (``docs/hosts.md``). :mod:`.bridge` is the DDS participant of a process, :mod:`.qos` the
quality of service of a connection, :mod:`.sample` how a message crosses, :mod:`.channel` the two
ends of a connection and how a process attaches them."""
