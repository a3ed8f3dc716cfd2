"""Errors of the bag library: each names the file and, when it is known, the byte where reading stopped."""

from __future__ import annotations

from pathlib import Path

from coco_core.errors import CocoError


class BagError(CocoError):
    """A bag that cannot be read (or written) as asked.

    ``path`` is the file or folder concerned, ``offset`` the byte position in that file where the
    problem was found (None when it is not about a position, e.g. a missing folder), ``detail`` says
    what was expected and what was found.
    """

    def __init__(self, path: str | Path, detail: str, offset: int | None = None) -> None:
        self.path = str(path)
        self.offset = offset
        self.detail = detail
        where = self.path if offset is None else f"{self.path} at byte {offset}"
        super().__init__(f"{where}: {detail}")


class MessageTypeError(BagError):
    """A message type whose Python class cannot be found (its package is not installed)."""
