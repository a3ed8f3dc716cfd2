"""ROSInterface: ROS topics <-> CoCo ports, configured in XML (see :mod:`.component`, :mod:`.topic`)."""

from .topic import SpecError, TopicSpec, parse_spec, parse_specs

__all__ = ["SpecError", "TopicSpec", "parse_spec", "parse_specs"]
