"""``python -m coco_ros.palpation summary.json``: a palpation run's JSON summary in a few lines."""

from __future__ import annotations

import sys

from ..summary_cli import print_summary
from .summary import describe

if __name__ == "__main__":
    sys.exit(print_summary(sys.argv[1:], "coco_ros.palpation", "palpation", describe))
