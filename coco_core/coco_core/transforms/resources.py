"""Resolve ``package://`` URLs (and ``file://`` URLs, plain paths) to files, as ROS tools do.

A URDF names its meshes, and an application names its URDF, as ``package://<package>/<path>``. The
package's share directory is looked up, in this order:

1. the ament index (``ament_index_python``, imported only when needed; it reads ``AMENT_PREFIX_PATH``);
2. ``<prefix>/share/<package>`` for each prefix of ``AMENT_PREFIX_PATH`` then ``CMAKE_PREFIX_PATH``
   (workspaces that are not indexed, or a missing ``ament_index_python``);
3. ``cmeel.prefix/share/<package>`` in every site-packages directory (pip wheels of robotics
   packages, e.g. ``example-robot-data``, install their share directories there), then
   ``sys.prefix/share/<package>``.

When nothing matches, the error names the URL and every place that was tried.
"""

from __future__ import annotations

import os
import sys
import sysconfig
from pathlib import Path
from urllib.parse import unquote, urlparse

from ..errors import ResourceNotFoundError

PACKAGE_SCHEME = "package://"
FILE_SCHEME = "file://"


def share_directories() -> list[Path]:
    """The ``share`` directories searched after the ament index, in search order, without duplicates."""
    candidates: list[Path] = []
    for variable in ("AMENT_PREFIX_PATH", "CMAKE_PREFIX_PATH"):
        for prefix in os.environ.get(variable, "").split(os.pathsep):
            if prefix:
                candidates.append(Path(prefix) / "share")
    site_dirs = [sysconfig.get_paths().get("purelib"), sysconfig.get_paths().get("platlib")]
    site_dirs += [entry for entry in sys.path if entry.endswith(("site-packages", "dist-packages"))]
    for site_dir in site_dirs:
        if site_dir:
            candidates.append(Path(site_dir) / "cmeel.prefix" / "share")
    candidates.append(Path(sys.prefix) / "share")
    return list(dict.fromkeys(candidates))


def package_share_directory(package: str, tried: list[str] | None = None) -> Path:
    """The share directory of ``package`` (see the module docstring for the search order).

    Raises :class:`ResourceNotFoundError` listing the places tried; ``tried``, when given, receives
    them too.
    """
    places = tried if tried is not None else []
    share = _from_ament_index(package, places)
    if share is not None:
        return share
    for directory in share_directories():
        candidate = directory / package
        if candidate.is_dir():
            return candidate
        places.append(str(candidate))
    raise ResourceNotFoundError(f"package {package!r} not found; tried: {', '.join(places)}")


def _from_ament_index(package: str, places: list[str]) -> Path | None:
    if not os.environ.get("AMENT_PREFIX_PATH"):
        places.append("ament index (AMENT_PREFIX_PATH is not set)")
        return None
    try:
        from ament_index_python.packages import get_package_prefix
    except ImportError:
        places.append("ament index (ament_index_python is not installed)")
        return None
    try:
        prefix = get_package_prefix(package)
    except (LookupError, ValueError, OSError):  # not indexed, invalid name, no search path
        places.append("ament index")
        return None
    share = Path(prefix) / "share" / package
    if share.is_dir():
        return share
    places.append(f"ament index ({share} is indexed but missing)")
    return None


def resolve(url: str | os.PathLike[str], relative_to: str | os.PathLike[str] | None = None) -> Path:
    """The file a ``package://`` URL, a ``file://`` URL or a path names.

    Relative paths are taken relative to ``relative_to`` (e.g. the URDF's directory, for its meshes)
    or the working directory. The file itself must exist: a missing one is a
    :class:`ResourceNotFoundError` naming it (and, for a package URL, the package directory found).
    """
    text = os.fspath(url)
    if text.startswith(PACKAGE_SCHEME):
        package, _, inner = text[len(PACKAGE_SCHEME):].partition("/")
        if not package:
            raise ResourceNotFoundError(f"{text}: a package URL must look like package://<package>/<path>")
        tried: list[str] = []
        try:
            share = package_share_directory(package, tried)
        except ResourceNotFoundError:
            raise ResourceNotFoundError(
                f"cannot resolve {text}: package {package!r} not found; tried: {', '.join(tried)}") from None
        path = share / unquote(inner)
        if not path.exists():
            raise ResourceNotFoundError(f"cannot resolve {text}: package {package!r} is {share}, "
                                        f"but {path} does not exist")
        return path
    if text.startswith(FILE_SCHEME):
        parsed = urlparse(text)
        path = Path(unquote(parsed.netloc + parsed.path))
    else:
        path = Path(text).expanduser()
    if not path.is_absolute() and relative_to is not None:
        path = Path(relative_to) / path
    if not path.exists():
        raise ResourceNotFoundError(f"file {path} does not exist" + (f" (from {text})" if str(path) != text else ""))
    return path
