"""``python -m coco_ros.teleop summary.json``: a teleop run's JSON summary in a few lines."""

from __future__ import annotations

import sys

from ..summary_cli import print_summary
from .summary import describe

if __name__ == "__main__":
    sys.exit(print_summary(sys.argv[1:], "coco_ros.teleop", "teleop", describe))
