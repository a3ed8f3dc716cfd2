"""``python -m coco_ros.<app> summary.json``: what every application's summary printer shares.

An application writes its summary as JSON at the stop (the file keeps every figure for a script);
its package's ``__main__`` prints it for a person with the application's own ``describe``, as
``scripts/run_app.sh`` does after a run.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any, Callable


def print_summary(argv: list[str], program: str, what: str, describe: Callable[[dict[str, Any]], str]) -> int:
    """Print the summary file named by ``argv`` with ``describe``; 2 on a wrong command line, 1 when
    the file cannot be read."""
    if len(argv) != 1:
        print(f"usage: python -m {program} summary.json", file=sys.stderr)
        return 2
    try:
        summary = json.loads(Path(argv[0]).read_text())
    except (OSError, ValueError) as error:
        print(f"cannot read the {what} summary {argv[0]}: {error}", file=sys.stderr)
        return 1
    print(describe(summary))
    return 0
