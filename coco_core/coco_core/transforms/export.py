"""Diagnostics exports of a transformation graph: JSON (the whole graph at any time) and graphviz DOT.

``to_json`` is :meth:`TransformGraph.to_dict` made strictly JSON-valid (numpy arrays and scalars as
plain lists and numbers, non-finite numbers as ``null``), with each edge's value also given as a
translation and a quaternion ``(x, y, z, w)`` so that a person can read it. ``to_dot`` draws frames
as nodes and edges as arrows from parent to child, labelled with their kind and, for joints, the
joint's name and value; the kinds are told apart by line style (static solid, dynamic dashed,
axis bold).
"""

from __future__ import annotations

import enum
import json
import math
import time as _time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from . import se3

if TYPE_CHECKING:
    from .graph import TransformGraph

EDGE_STYLES = {"static": "solid", "dynamic": "dashed", "axis": "bold"}
"""Graphviz line style of each edge kind."""


def jsonable(value: Any) -> Any:
    """``value`` with numpy arrays/scalars, tuples, sets and enums turned into JSON types.

    Non-finite floats become ``None``: ``NaN`` is not JSON, and browsers' ``JSON.parse`` rejects it.
    """
    if isinstance(value, dict):
        return {str(key): jsonable(item) for key, item in value.items()}
    if isinstance(value, (list, tuple, set, frozenset)):
        return [jsonable(item) for item in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.generic):
        return jsonable(value.item())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, enum.Enum):
        return jsonable(value.value)
    if value is None or isinstance(value, (str, int, bool)):
        return value
    return str(value)


def pose(transform: np.ndarray | list) -> dict[str, list[float]]:
    """A 4x4 transform as ``matrix`` (row-major lists), ``translation`` and ``quaternion`` (x, y, z, w)."""
    matrix = np.asarray(transform, dtype=float)
    translation, quaternion = se3.to_pose(matrix)
    return {"matrix": jsonable(matrix), "translation": jsonable(translation), "quaternion": jsonable(quaternion)}


def edge_dict(described: dict[str, Any]) -> dict[str, Any]:
    """One entry of ``to_dict()["edges"]``, JSON-ready, plus translation and quaternion of its value."""
    edge = jsonable(described)
    transform = edge.get("transform")
    if transform is not None:
        try:
            readable = pose(transform)
        except (ValueError, TypeError, ZeroDivisionError):  # not a rigid transform: leave it as it is
            pass
        else:
            edge["translation"], edge["quaternion"] = readable["translation"], readable["quaternion"]
    return edge


def graph_dict(graph: TransformGraph) -> dict[str, Any]:
    """The whole graph, JSON-ready: ``to_dict()`` with readable edge values and the wall time it was taken."""
    described = graph.to_dict()
    result = jsonable({key: value for key, value in described.items() if key != "edges"})
    result["edges"] = [edge_dict(edge) for edge in described.get("edges", [])]
    result["time"] = _time.time()
    return result


def to_json(graph: TransformGraph, indent: int | None = None) -> str:
    """The whole graph as JSON: version, frames, edges (kind, value, translation, quaternion, stamps,
    joints), models, and the wall time of the snapshot."""
    return json.dumps(graph_dict(graph), indent=indent, allow_nan=False)


def _quote(text: str) -> str:
    """A DOT double-quoted string; ``\\n`` inside ``text`` stays a DOT line break."""
    return '"' + str(text).replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


def _number(value: Any) -> str:
    return "?" if value is None else f"{float(value):.4g}"


def _edge_label(edge: dict[str, Any]) -> str:
    lines = [edge.get("kind", "?")]
    if edge.get("joint"):
        joint = f"{edge['joint']}"
        if "value" in edge:
            joint += f" = {_number(edge['value'])}"
        if edge.get("joint_type"):
            joint += f" ({edge['joint_type']})"
        lines.append(joint)
    if edge.get("model"):
        lines.append(f"model {edge['model']}")
    if edge.get("kind") == "dynamic":
        lines.append(f"stamp {edge['stamp']:.3f}" if edge.get("stamp") is not None else "no sample")
    if edge.get("error"):
        lines.append(f"error: {edge['error']}")
    return "\n".join(lines)


def to_dot(graph: TransformGraph, name: str = "transforms") -> str:
    """The graph in graphviz DOT: frames as nodes, edges parent -> child labelled with kind and joint,
    styled by kind (static solid, dynamic dashed, axis bold)."""
    described = graph.to_dict()
    lines = [
        f"digraph {_quote(name)} {{",
        "  rankdir=TB;",
        '  node [shape=box, style=rounded, fontname="Helvetica"];',
        '  edge [fontname="Helvetica", fontsize=10];',
    ]
    for frame in described["frames"]:
        lines.append(f"  {_quote(frame)};")
    for edge in described["edges"]:
        kind = edge.get("kind", "")
        attributes = [f"label={_quote(_edge_label(edge))}", f"style={EDGE_STYLES.get(kind, 'dotted')}"]
        if edge.get("error"):
            attributes.append("color=red")
        lines.append(f"  {_quote(edge['parent'])} -> {_quote(edge['child'])} [{', '.join(attributes)}];")
    lines.append("}")
    return "\n".join(lines) + "\n"


def write_dot(graph: TransformGraph, path: str | Path, name: str = "transforms") -> Path:
    """Write :func:`to_dot` to ``path`` (render it with ``dot -Tsvg path -o graph.svg``); returns the path."""
    path = Path(path)
    path.write_text(to_dot(graph, name), encoding="utf-8")
    return path
