"""Message definitions as rosbag2 stores them in MCAP schemas (encoding ``ros2msg``).

A schema holds the *complete* definition: the type's own ``.msg`` text first, then every type it
uses, recursively, each once, preceded by a line of 80 ``=`` and a ``MSG: pkg/Name`` line. Tools that
do not have the packages (Foxglove, rosbags, PlotJuggler) decode the bag from this text alone.

The texts come from the ``.msg`` files rosidl installs under ``share/<pkg>/msg/``; the order of the
dependencies and the spelling of their names follow rosbag2's ``LocalMessageDefinitionSource``
(dependencies sorted by name, depth first, named as written in the field). The type description hash
(RIHS01) comes from the ``.json`` file rosidl installs beside the ``.msg``.
"""

from __future__ import annotations

import json
import os
import re
import sys
import threading
from pathlib import Path

from coco_core.errors import BagError

from .message_types import normalize_type

DELIMITER = "=" * 80
ENCODING = "ros2msg"

# Same pattern as rosbag2: the type at the start of each field line ("foo_msgs/Bar" in "foo_msgs/Bar[] bar").
_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
_PRIMITIVES = frozenset(
    "bool byte char float32 float64 int8 uint8 int16 uint16 int32 uint32 int64 uint64 string".split()
)
_MAX_DEPTH = 50


def share_directories() -> list[Path]:
    """Where installed packages keep ``share/<pkg>``: AMENT_PREFIX_PATH, then this Python's prefix."""
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes += [sys.prefix, sys.base_prefix]
    seen: list[Path] = []
    for prefix in prefixes:
        share = Path(prefix) / "share"
        if share.is_dir() and share not in seen:
            seen.append(share)
    return seen


def dependencies(text: str, package: str) -> list[str]:
    """Types used by the fields of a ``.msg`` text, sorted, as rosbag2 names them (``pkg/Name``)."""
    found = set()
    for match in _FIELD_TYPE.finditer(text):
        name = match.group(1)
        if name in _PRIMITIVES:
            continue
        found.add(name if "/" in name else f"{package}/{name}")
    return sorted(found)


class DefinitionSource:
    """Reads and caches ``.msg`` texts and type hashes; thread-safe."""

    def __init__(self, share_dirs: list[Path] | None = None) -> None:
        self._share_dirs = share_dirs
        self._texts: dict[str, str] = {}
        self._full: dict[str, str] = {}
        self._lock = threading.Lock()

    @property
    def share_dirs(self) -> list[Path]:
        if self._share_dirs is None:
            self._share_dirs = share_directories()
        return self._share_dirs

    def _file(self, type_name: str, extension: str) -> Path | None:
        package, namespace, name = normalize_type(type_name).split("/")
        for share in self.share_dirs:
            candidate = share / package / namespace / f"{name}{extension}"
            if candidate.is_file():
                return candidate
        return None

    def msg_text(self, type_name: str) -> str:
        """The ``.msg`` text of one type (no dependencies)."""
        full = normalize_type(type_name)
        text = self._texts.get(full)
        if text is not None:
            return text
        path = self._file(full, ".msg")
        if path is not None:
            text = path.read_text(encoding="utf-8")
        else:
            searched = ", ".join(str(s) for s in self.share_dirs) or "(none found)"
            package, namespace, name = full.split("/")
            raise BagError(
                full,
                f"no message definition: expected {package}/{namespace}/{name}.msg under one of the "
                f"share directories {searched}; install the package that provides {full!r} "
                "or pass the definition text explicitly",
            )
        self._texts[full] = text
        return text

    def full_text(self, type_name: str) -> str:
        """The complete ``ros2msg`` definition of ``type_name``, as rosbag2 writes it into a schema."""
        full = normalize_type(type_name)
        with self._lock:
            cached = self._full.get(full)
            if cached is None:
                cached = self._full[full] = self._compose(full)
        return cached

    def _compose(self, root: str) -> str:
        seen: set[str] = set()

        def append(type_name: str, depth: int) -> str:
            if depth <= 0:
                detail = f"message definition nests deeper than {_MAX_DEPTH} levels at {type_name!r}"
                raise BagError(root, detail)
            text = self.msg_text(type_name)
            package = type_name.split("/")[0]
            result = text
            for dependency in dependencies(text, package):
                if dependency not in seen:
                    seen.add(dependency)
                    result += f"\n{DELIMITER}\nMSG: {dependency}\n" + append(dependency, depth - 1)
            return result

        return append(root, _MAX_DEPTH)

    def type_hash(self, type_name: str) -> str:
        """The RIHS01 type description hash, or '' when rosidl left no ``.json`` for the type."""
        full = normalize_type(type_name)
        path = self._file(full, ".json")
        if path is not None:
            try:
                for entry in json.loads(path.read_text(encoding="utf-8")).get("type_hashes", []):
                    if entry.get("type_name") == full:
                        return str(entry.get("hash_string", ""))
            except (OSError, ValueError):
                return ""
        return ""
