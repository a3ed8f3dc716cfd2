"""ROSInterface: ROS topics <-> CoCo ports, configured in XML (see :mod:`.component`, :mod:`.topic`)."""

from coco_core.errors import SpecError

from .topic import TopicSpec, parse_spec, parse_specs

__all__ = ["SpecError", "TopicSpec", "parse_spec", "parse_specs"]
