"""Replay and record rosbag2 MCAP bags, the CoCo way.

- :class:`PlaybackClock` (``clock``): maps bag time to wall time; rate factor, as fast as possible,
  pause / resume / step; the simulated time a ``/clock`` publisher sends.
- :class:`Player` (``player``): walks a bag (start offset, duration, loop, topic filter, remapping),
  delivering latched messages (``/tf_static``) first at the start of every pass, paced by the clock;
  independent of where the messages go.
- :class:`BagReplay` (``component``): a CoCo component writing the messages into output ports
  (converted to CoCo values where a converter exists), no DDS involved.
- :class:`BagRecorder` (``recorder``): a CoCo component writing its input ports into a rosbag2 bag.
- ``coco-replay`` (``cli``): republishes a bag's raw CDR bytes on ROS topics with rclpy.
"""

from .clock import PlaybackClock
from .player import Played, Player, parse_remaps

__all__ = ["PlaybackClock", "Played", "Player", "parse_remaps"]
