"""rosbag2 bags in MCAP storage: read (replay) and write (record) without the rosbag2 C++ stack.

- :class:`BagReader`: a bag folder or ``.mcap`` file; topics with types and offered QoS, messages in
  log-time order with lazy rclpy deserialization, the latched messages a replay from an offset must
  deliver first, and reading that survives truncated or corrupt files.
- :class:`BagWriter`: a rosbag2-compatible bag folder (``<name>_0.mcap`` + ``metadata.yaml``)
  that rosbag2, rosbags and Foxglove read; flushed regularly so an interruption loses little.
"""

from coco_core.errors import BagError, MessageTypeError

from .qos import TF_STATIC, Qos
from .reader import BagMessage, BagReader
from .topic import TopicInfo
from .writer import BagWriter

__all__ = [
    "BagError",
    "BagMessage",
    "BagReader",
    "BagWriter",
    "MessageTypeError",
    "Qos",
    "TF_STATIC",
    "TopicInfo",
]
