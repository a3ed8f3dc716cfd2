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
from .registration import (AverageResult, MeasurementPath, PathStatistics, Registration, RegistrationError,
                           RegistrationResult, average_quaternions, average_transforms, robust_average,
                           transform_residuals)

__all__ += [
    "AverageResult", "MeasurementPath", "PathStatistics", "Registration", "RegistrationError", "RegistrationResult",
    "average_quaternions", "average_transforms", "robust_average", "transform_residuals",
]

# URDF support imports Pinocchio, so it is loaded only when one of its names is asked for.
_URDF_NAMES = ("UrdfError", "UrdfModel", "load_urdf")
__all__ += list(_URDF_NAMES)


def __getattr__(name: str):
    if name in _URDF_NAMES:
        from . import urdf

        return getattr(urdf, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

# Diagnostics: JSON / DOT exports and the REST + WebSocket server with its web page.
from .export import graph_dict, to_dot, to_json, write_dot  # noqa: E402
from .server import TransformServer  # noqa: E402

__all__ += ["TransformServer", "graph_dict", "to_dot", "to_json", "write_dot"]
