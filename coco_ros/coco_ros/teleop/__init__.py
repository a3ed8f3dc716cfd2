"""The Baxter teleoperation replay application's components (``config/baxter_teleop_replay.xml``).

- :class:`~.distance.EndEffectorDistance` (the paper's *UpdateColorCalc*): gripper-to-bowl distance
  and the colour the display renders for it.
- :class:`~.summary.TeleopSummary`: a CSV of every distance and a JSON summary at the stop;
  ``python -m coco_ros.teleop summary.json`` prints that summary in a few lines.
"""

from .distance import EndEffectorDistance, distance_color
from .summary import TeleopSummary

__all__ = ["EndEffectorDistance", "TeleopSummary", "distance_color"]
