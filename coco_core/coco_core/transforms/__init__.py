"""The transformation graph: CoCo's third graph, usable as a plain library.

Frames joined by static, dynamic (timestamped) and axis (single-axis joint) edges; cached, versioned
lookups with change callbacks; URDF robots through Pinocchio. See :mod:`.graph` for the semantics.
"""

from .edges import AxisEdge, DynamicEdge, Edge, EdgeKind, ExtrapolationError, JointType, StaticEdge
from .graph import KinematicModel, ModelEdge, Query, TransformError, TransformGraph

__all__ = [
    "AxisEdge", "DynamicEdge", "Edge", "EdgeKind", "ExtrapolationError", "JointType", "KinematicModel",
    "ModelEdge", "Query", "StaticEdge", "TransformError", "TransformGraph",
]
