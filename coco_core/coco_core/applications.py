"""Finding the application file a launcher is asked to run, from any folder.

``ros2 launch PKG FILE`` finds a launch file installed by a package; a CoCo launcher finds an
application the same ways, tried in this order:

1. a file: ``config/demo_pipeline.xml`` (relative to the working directory) or an absolute path;
2. a URL: ``package://coco_ros/config/demo_pipeline.xml`` (also ``file://``), resolved as a URDF's
   (:mod:`coco_core.transforms.resources`), so ``$(find-pkg-share coco_ros)/config/...`` names the
   same file;
3. the name of an application a package installs in ``share/<package>/config/``:
   ``demo_pipeline.xml`` or ``demo_pipeline``. A name that two packages install is an error that
   lists both URLs to choose from.

A name found nowhere is an error listing the places tried and the installed applications.
"""

from __future__ import annotations

import os
from pathlib import Path

from .errors import ConfigError, ResourceNotFoundError
from .transforms.resources import FILE_SCHEME, PACKAGE_SCHEME, resolve

APPLICATIONS = "config"
"""The folder of a package's share directory that holds its application files."""


def installed_applications() -> dict[str, list[Path]]:
    """Application files installed by the packages of the ament index, by file name."""
    if not os.environ.get("AMENT_PREFIX_PATH"):
        return {}
    try:
        from ament_index_python.packages import get_packages_with_prefixes
    except ImportError:
        return {}
    found: dict[str, list[Path]] = {}
    for package, prefix in sorted(get_packages_with_prefixes().items()):
        folder = Path(prefix) / "share" / package / APPLICATIONS
        if folder.is_dir():
            for path in sorted(folder.glob("*.xml")):
                found.setdefault(path.name, []).append(path)
    return found


def find_application(name: str | os.PathLike[str]) -> Path:
    """The application file ``name`` designates (see the module docstring for the order)."""
    text = os.fspath(name)
    if text.startswith((PACKAGE_SCHEME, FILE_SCHEME)):
        try:
            return resolve(text)
        except ResourceNotFoundError as error:
            raise ConfigError(f"application: {error}") from None
    path = Path(text).expanduser()
    if path.exists() or path.is_absolute() or len(path.parts) > 1:
        return path  # a path: the loader says what is wrong with it
    installed = installed_applications()
    matches = installed.get(text) or installed.get(f"{text}.xml") or []
    if len(matches) == 1:
        return matches[0]
    if matches:
        urls = ", ".join(f"{PACKAGE_SCHEME}{m.parents[1].name}/{APPLICATIONS}/{m.name}" for m in matches)
        raise ConfigError(f"application {text!r} is installed by several packages: name one of {urls}")
    names = ", ".join(sorted(installed)) or "none (is a workspace's install/setup.bash sourced?)"
    raise ConfigError(f"application {text!r} not found: no such file in {Path.cwd()}, and no installed package "
                      f"has it in share/<package>/{APPLICATIONS}/; installed applications: {names}")
