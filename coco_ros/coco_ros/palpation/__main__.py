"""``python -m coco_ros.palpation summary.json``: a palpation run's JSON summary in a few lines."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .summary import describe


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: python -m coco_ros.palpation summary.json", file=sys.stderr)
        return 2
    try:
        summary = json.loads(Path(argv[0]).read_text())
    except (OSError, ValueError) as error:
        print(f"cannot read the palpation summary {argv[0]}: {error}", file=sys.stderr)
        return 1
    print(describe(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
