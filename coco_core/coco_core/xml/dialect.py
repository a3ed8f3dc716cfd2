"""Which dialect a file is written in: the original CoCo's, or this project's (with its extensions).

The original C++ CoCo parser ignores elements it does not know, and the original Python launcher
still expands the substitutions inside them (``<test value="$(eval ...)"/>`` under ``<package>`` in
its samples), so its files may carry elements that mean nothing to any launcher. This loader is
strict: an unknown element is an error naming what was expected, since it is usually a typo. To
load the original's files unchanged without giving that up, each file is read in one of two
dialects:

- a file that uses one of this project's extensions (:data:`EXTENSION_ELEMENTS`,
  :data:`EXTENSION_ATTRIBUTES`) was written for this project: unknown elements are errors;
- any other file is read as the original CoCo reads it: an unknown element is a warning (file:line)
  and is ignored, after its substitutions were expanded (a wrong one is still an error, as in the
  original launcher).

The choice is made per file (an included file decides for itself), from the whole file, before
anything is read, so it does not depend on where in the file the extension stands.
"""

from __future__ import annotations

from .tree import Element

EXTENSION_ELEMENTS = ("choice", "composite", "filter", "ports", "process", "transforms")
"""Elements the original CoCo does not have."""
EXTENSION_ATTRIBUTES: dict[str, tuple[str, ...]] = {
    "package": ("on_error",),
    "component": ("on_error",),
    "connection": ("event",),
    "activity": ("name",),
    "farm": ("name",),
    "schedule": ("main", "min_period", "nice"),
    "schedulepolicy": ("main", "min_period", "nice"),
    "src": ("activity",),
    "dest": ("activity",),
}
"""Attributes, by element, that the original CoCo does not have."""


def extension_of(root: Element) -> Element | None:
    """The first element of ``root``'s tree (document order) that uses an extension of this
    project, or None: the file is then in the original CoCo's dialect."""
    pending = [root]
    while pending:
        element = pending.pop()
        if element.tag in EXTENSION_ELEMENTS:
            return element
        if any(name in element.attributes for name in EXTENSION_ATTRIBUTES.get(element.tag, ())):
            return element
        pending.extend(reversed(element.children))
    return None
