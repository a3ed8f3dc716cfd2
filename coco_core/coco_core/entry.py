"""``coco-launch``'s entry point: the launcher's signal handling first, then the runtime.

Importing the launcher loads the runtime (numpy, the transformation graph, ...), which takes a
noticeable part of a second; a Ctrl-C in that time would interrupt an import with a traceback. So
the installed script starts here, where only the signal handling is imported before it is in force.
"""

from __future__ import annotations

import sys

from .signals import LaunchSignals


def main(early: list[int] | None = None) -> int:
    """``early``: signals the installed script recorded before this ran (they count as received)."""
    signals = LaunchSignals().install()
    signals.received.extend(early or ())
    from .launcher import main as launch

    return launch(signals=signals)


if __name__ == "__main__":
    sys.exit(main())
