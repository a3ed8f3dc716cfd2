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
from .averaging import AverageResult, average_quaternions, average_transforms, robust_average, transform_residuals
from .registration import MeasurementPath, PathStatistics, Registration, RegistrationError, RegistrationResult

__all__ += [
    "AverageResult", "MeasurementPath", "PathStatistics", "Registration", "RegistrationError", "RegistrationResult",
    "average_quaternions", "average_transforms", "robust_average", "transform_residuals",
]

# URDF support imports Pinocchio, so it is loaded only when one of its names is asked for.
_URDF_NAMES = ("UrdfError", "UrdfModel", "load_urdf")
__all__ += list(_URDF_NAMES)


# The diagnostics server (REST, WebSocket, web page) imports http.server and socketserver, about a
# fifth of the runtime's import time: it is loaded only when it is served.
_SERVER_NAMES = ("TransformServer",)
__all__ += list(_SERVER_NAMES)


def __getattr__(name: str):
    if name in _URDF_NAMES:
        from . import urdf

        return getattr(urdf, name)
    if name in _SERVER_NAMES:
        from . import server

        return getattr(server, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

# Diagnostics: JSON / DOT exports.
from .export import graph_dict, to_dot, to_json, write_dot  # noqa: E402

__all__ += ["graph_dict", "to_dot", "to_json", "write_dot"]
