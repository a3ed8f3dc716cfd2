"""A folder that keeps the parts made from mesh files between processes: ``COCO_MESH_CACHE``.

Why: reading a robot's mesh files and simplifying them is most of a display's start (Baxter's: ~2.5 s
of CPU, in every process that draws it, at every launch). With ``COCO_MESH_CACHE=<folder>`` the first
process to make the parts of a mesh file writes them there and later processes read them back (a few
milliseconds). Unset (the default), nothing is kept between processes.

An entry is named by a hash of everything its parts depend on: the file (path, size, modification
time), what is baked in (origin, scale, colour, fraction kept) and the source of the code that makes
them (:mod:`.mesh` and this module), so an edited mesh or a new version of that code makes new
entries, never reads old ones. Entries are written whole (a temporary file renamed), so processes
that make the same entry at once each read a complete one; an entry that cannot be read is made again.
"""

from __future__ import annotations

import hashlib
import logging
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from . import mesh
from .mesh import MeshPart

log = logging.getLogger("coco.display")

ENVIRONMENT = "COCO_MESH_CACHE"
"""The environment variable that names the folder (unset or empty: no folder)."""


def _code_version() -> bytes:
    return hashlib.sha256(Path(mesh.__file__).read_bytes() + Path(__file__).read_bytes()).digest()


_CODE = _code_version()


def entry(key: tuple[Any, ...]) -> Path | None:
    """The file of ``key``'s parts in the folder ``COCO_MESH_CACHE`` names, or None without one."""
    folder = os.environ.get(ENVIRONMENT, "")
    if not folder:
        return None
    return Path(folder) / f"{hashlib.sha256(_CODE + repr(key).encode()).hexdigest()}.npz"


def read(path: Path) -> list[MeshPart] | None:
    """The parts kept in ``path``, or None when there are none (or they cannot be read: made again)."""
    try:
        with np.load(path, allow_pickle=False) as kept:
            def field(name: str, index: int) -> np.ndarray | None:
                return kept[f"{name}_{index}"] if f"{name}_{index}" in kept else None

            return [MeshPart(kept[f"positions_{index}"], kept[f"indices_{index}"], field("colors", index),
                             field("uvs", index), field("texture", index)) for index in range(int(kept["count"]))]
    except (OSError, ValueError, KeyError):
        return None


def write(path: Path, parts: list[MeshPart]) -> None:
    """Keep ``parts`` in ``path`` (whole or not at all); a folder that cannot be written is logged,
    and the next process makes the parts again."""
    arrays: dict[str, np.ndarray] = {"count": np.array(len(parts))}
    for index, part in enumerate(parts):
        arrays.update({f"{name}_{index}": array for name, array in part.arrays().items()})
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, temporary = tempfile.mkstemp(dir=path.parent, suffix=".partial")
        try:
            with os.fdopen(handle, "wb") as file:
                np.savez(file, **arrays)  # type: ignore[arg-type]  # savez takes its arrays as keywords
            os.replace(temporary, path)
        finally:
            if os.path.exists(temporary):
                os.unlink(temporary)
    except OSError as error:
        log.warning("%s: cannot keep the parts of a mesh there: %s", ENVIRONMENT, error)
