"""The launchers' entry point: the launcher's signal handling first, then the runtime.

Importing the launcher loads the runtime (numpy, the transformation graph, ...), which takes a
noticeable part of a second; a Ctrl-C in that time would interrupt an import with a traceback. So
the installed script starts here, where only the signal handling is imported before it is in force.
"""

from __future__ import annotations

import importlib
import sys

from .signals import LaunchSignals


def main(early: list[int] | None = None, launcher: str = "coco_core.launcher") -> int:
    """Run ``launcher``'s ``main`` with the launcher's signal handling in force from now on;
    ``early``: signals the installed script recorded before this ran (they count as received). The
    ROS launcher's script starts here too, with ``launcher="coco_ros.launcher"``."""
    signals = LaunchSignals().install(early or ())
    launch = importlib.import_module(launcher).main
    code: int = launch(signals=signals)
    return signals.finish(code)


if __name__ == "__main__":
    sys.exit(main())
