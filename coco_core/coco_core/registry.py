"""Component registry: from the ``<task>`` name of an application file to a component class.

Packages register components through the ``coco.components`` entry-point group
(``MovingAverage = coco_core.demo.moving_average:MovingAverage`` in ``setup.py``), so a file can name
any installed component, a user's own package included, without the runtime importing anything it
does not need. ``<task>`` may also be a full ``package.module:Class`` path, and scripts can register
classes in-process with :func:`register`.
"""

from __future__ import annotations

import functools
import importlib
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Callable, TypeVar

from .component import Component
from .errors import CocoError, did_you_mean, excerpt, UnknownComponentError

GROUP = "coco.components"
MAX_PATH_PARTS = 32
"""The most dotted parts a ``package.module:Class`` path may have (real ones have 2 to 6): importing a
module 5,000 packages deep exhausts the import system's recursion before it finds nothing."""

C = TypeVar("C", bound=type[Component])

_in_process: dict[str, type[Component]] = {}


@dataclass(frozen=True)
class Registration:
    """Where a component name comes from."""

    name: str
    target: str
    """``module:Class``."""
    library: str
    """The Python package (top-level module) that provides it."""


@functools.cache
def _installed() -> dict[str, Registration]:
    """The components installed packages register, scanned once per process: a scan reads the
    metadata of every installed distribution, and scanning once per component made a ``--check``
    of 4,000 components take 150 s here (1.3 s with one scan)."""
    return {entry.name: Registration(entry.name, entry.value, entry.value.split(".", 1)[0].split(":")[0])
            for entry in entry_points(group=GROUP)}


def registrations() -> dict[str, Registration]:
    """Every registered component name, entry points and in-process registrations."""
    found = dict(_installed())
    for name, cls in _in_process.items():
        found[name] = Registration(name, f"{cls.__module__}:{cls.__qualname__}", cls.__module__.split(".")[0])
    return found


def register(name: str | None = None) -> Callable[[C], C]:
    """Class decorator registering a component in this process (scripts, tests, notebooks)."""

    def decorate(cls: C) -> C:
        _in_process[name or cls.__name__] = cls
        return cls

    return decorate


def _import(target: str) -> type[Component]:
    module_name, _, class_name = target.partition(":")
    obj: object = importlib.import_module(module_name)
    for part in class_name.split("."):
        obj = getattr(obj, part)
    if not (isinstance(obj, type) and issubclass(obj, Component)):
        raise CocoError(f"{target} is not a coco_core.Component subclass")
    return obj


def _check_path(task: str) -> None:
    """Refuse a ``package.module:Class`` path that cannot name a class, before importing anything."""
    module_name, _, class_name = task.partition(":")
    modules, classes = module_name.split("."), class_name.split(".")
    if len(modules) + len(classes) > MAX_PATH_PARTS or not all(part.isidentifier() for part in modules + classes):
        raise UnknownComponentError(
            f"cannot import component {excerpt(task)}: expected package.module:Class, Python names separated "
            f"by dots (at most {MAX_PATH_PARTS} of them)")


def load(task: str, library: str = "") -> type[Component]:
    """The component class registered as ``task`` (by ``library`` when given)."""
    if ":" in task:
        _check_path(task)
        try:
            return _import(task)
        except (ImportError, AttributeError) as error:
            raise UnknownComponentError(f"cannot import component {task}: {error}") from None
    known = registrations()
    registration = known.get(task)
    if registration is None:
        in_library = sorted(n for n, r in known.items() if r.library == library) if library else []
        scope = f" in library {library!r} (which provides: {', '.join(in_library) or 'nothing'})" if library else ""
        raise UnknownComponentError(
            f"unknown component {excerpt(task)}{scope}; {did_you_mean(task, list(known))}")
    if library and registration.library != library:
        raise UnknownComponentError(
            f"component {task!r} is provided by library {registration.library!r}, not {library!r}")
    return _in_process.get(task) or _import(registration.target)
