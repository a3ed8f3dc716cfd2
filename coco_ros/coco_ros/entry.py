"""The ROS launcher's entry point (``lib/coco_ros/launcher``): the launcher's signal handling
first, then rclpy and the runtime, whose imports take a noticeable part of a second (see
``coco_core.entry``)."""

from __future__ import annotations

import sys

from coco_core.signals import LaunchSignals


def main(early: list[int] | None = None) -> int:
    """``early``: signals the installed script recorded before this ran (they count as received)."""
    signals = LaunchSignals().install()
    signals.received.extend(early or ())
    from .launcher import main as launch

    return launch(signals=signals)


if __name__ == "__main__":
    sys.exit(main())
