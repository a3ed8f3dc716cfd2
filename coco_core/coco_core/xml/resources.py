"""Finding a file named in an application: next to the file that names it, then in the resource paths.

Used for ``<include>`` and for ``type="file"`` attributes, so both follow one rule and a failure
lists the same kind of places tried.
"""

from __future__ import annotations

import os
from collections.abc import Sequence


def find_resource(name: str, directory: str, paths: Sequence[str]) -> tuple[str | None, list[str]]:
    """The absolute path of an existing ``name`` and the candidates tried (None when none exists).

    An absolute ``name`` is only checked; a relative one is tried in ``directory`` first, then in
    each of ``paths`` in order.
    """
    if os.path.isabs(name):
        candidates = [os.path.normpath(name)]
    else:
        bases = (directory, *paths)
        candidates = list(dict.fromkeys(os.path.normpath(os.path.join(base, name)) for base in bases))
    for candidate in candidates:
        if os.path.exists(candidate):
            return candidate, candidates
    return None, candidates


def not_found_message(name: str, tried: Sequence[str]) -> str:
    """The end of the error for a resource that :func:`find_resource` did not find."""
    return f"{name!r} not found; tried: {', '.join(tried)}"
