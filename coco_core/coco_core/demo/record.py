"""What the demo components that record what they did write at their stop, for a check or a benchmark
in another process to read: one JSON file, written whole."""

from __future__ import annotations

import json
from pathlib import Path


def save_record(path: str | Path, record: object) -> None:
    """Write ``record`` as JSON to ``path``, whole (written beside it, then renamed): a reader that
    looks while the process stops never sees half of it."""
    partial = Path(path).with_suffix(".partial")
    partial.write_text(json.dumps(record))
    partial.replace(path)
