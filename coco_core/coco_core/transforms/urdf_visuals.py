"""The ``<visual>`` elements of a URDF, read in the same parse as its kinematics.

A robot's kinematics and its look come from one file. Kept together on the loaded model (as
pytransform3d's ``UrdfTransformManager`` keeps them), a display draws the very robot the
transformation graph moves, with no second file to name and no second parse to disagree with the
first. Mesh file names stay as written (``package://`` URLs or paths relative to the URDF): only a
display needs the files, so only a display resolves them, and a missing mesh never stops the
kinematics from loading.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from ..errors import UrdfError
from . import se3

SHAPES = ("mesh", "box", "sphere", "cylinder")
"""The URDF geometry elements a visual can hold."""


@dataclass(frozen=True)
class UrdfVisual:
    """One ``<visual>`` of a link, as declared (link name without the frame prefix)."""

    link: str
    origin: np.ndarray
    """``T_link_visual`` from the visual's ``<origin xyz rpy>``."""
    shape: str
    """One of :data:`SHAPES`."""
    filename: str = ""
    """The mesh file as written in the URDF (``mesh`` only)."""
    size: tuple[float, ...] = ()
    """Box sides, sphere radius, or cylinder radius and length."""
    scale: tuple[float, float, float] | None = None
    """The mesh's ``scale``, when it gives one."""
    color: tuple[float, float, float, float] | None = None
    """The material's RGBA (its own ``<color>`` or the robot-level material it names), when known."""


def parse_visuals(robot: ET.Element, label: str) -> list[UrdfVisual]:
    """Every visual of every link of a parsed ``<robot>``; ``label`` names the source in errors."""
    named: dict[str, tuple[float, float, float, float]] = {}
    for material in robot.findall("material"):
        rgba = _rgba(material, label)
        if rgba is not None and material.get("name"):
            named[material.get("name", "")] = rgba
    visuals = []
    for link in robot.findall("link"):
        name = link.get("name", "")
        for element in link.findall("visual"):
            visuals.append(_visual(element, name, named, label))
    return visuals


def _visual(element: ET.Element, link: str, named: dict[str, tuple[float, float, float, float]],
            label: str) -> UrdfVisual:
    where = f"{label}: a visual of link {link}"
    origin = _origin(element.find("origin"), where)
    material = element.find("material")
    color = None
    if material is not None:
        color = _rgba(material, label) or named.get(material.get("name", ""))
    geometry = element.find("geometry")
    shape = next((child for child in (geometry if geometry is not None else ()) if child.tag in SHAPES), None)
    if shape is None:
        raise UrdfError(f"{where} has no <geometry> with one of {', '.join(SHAPES)}")
    if shape.tag == "mesh":
        filename = shape.get("filename")
        if not filename:
            raise UrdfError(f"{where}: <mesh> has no filename")
        scale = _numbers(shape.get("scale"), where, "scale", (1, 3))
        if scale is not None and len(scale) == 1:  # one factor for all three axes
            scale = scale * 3
        return UrdfVisual(link, origin, "mesh", filename=filename, color=color,
                          scale=None if scale is None else (scale[0], scale[1], scale[2]))
    attributes = {"box": ("size",), "sphere": ("radius",), "cylinder": ("radius", "length")}[shape.tag]
    size: tuple[float, ...] = ()
    for attribute in attributes:
        values = _numbers(shape.get(attribute), where, attribute, (3,) if attribute == "size" else (1,))
        if values is None:
            raise UrdfError(f"{where}: <{shape.tag}> has no {attribute}")
        size += values
    return UrdfVisual(link, origin, shape.tag, size=size, color=color)


def _origin(element: ET.Element | None, where: str) -> np.ndarray:
    if element is None:
        return np.eye(4)
    xyz = _numbers(element.get("xyz"), where, "origin xyz", (3,)) or (0.0, 0.0, 0.0)
    rpy = _numbers(element.get("rpy"), where, "origin rpy", (3,)) or (0.0, 0.0, 0.0)
    return se3.make(se3.rpy_to_matrix(*rpy), xyz)


def _rgba(material: ET.Element, label: str) -> tuple[float, float, float, float] | None:
    color = material.find("color")
    if color is None:
        return None
    values = _numbers(color.get("rgba"), f"{label}: material {material.get('name', '')!r}", "rgba", (4,))
    return None if values is None else (values[0], values[1], values[2], values[3])


def _numbers(text: str | None, where: str, what: str, counts: tuple[int, ...]) -> tuple[float, ...] | None:
    """The numbers of an attribute like ``xyz="0 0 1"`` (None when absent); a clear error otherwise."""
    if text is None:
        return None
    try:
        values = tuple(float(value) for value in text.split())
    except ValueError:
        values = ()
    if len(values) not in counts:
        expected = " or ".join(str(count) for count in counts)
        raise UrdfError(f"{where}: {what}={text!r} must be {expected} number(s)")
    return values
