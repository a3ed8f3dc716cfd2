"""What a converter takes of a mirrored port's value, for the values that are not a converter's own.

- a pooled frame holding a mesh (a ``MeshReconstructor``'s slot) and a ``TriangleMesh``: the
  mesh's vertices and colours as a ``PointCloud`` (copied: the slot goes back to its writer at once),
  in the mesh's camera frame: the remote scene a viewer shows as a PointCloud2;
- a device's handle (a value with a ``position`` and a ``velocity``, a ``HapticDeviceState``): a
  ``FramePose`` of the handle, without rotation, in the topic's ``frame`` (the device's workspace);
- a ``Stamped`` value: its payload.

Anything else goes to the converter as it is.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from coco_core.errors import WrongTypeError
from coco_core.pool import Slot
from coco_core.stamps import Stamped
from coco_core.transforms.samples import FramePose
from coco_mr_vision.mesh import MeshInfo, TriangleMesh
from coco_mr_vision.pointcloud import PointCloud

HANDLE = "device"
"""The source frame name of a device's handle pose."""


def is_handle(cls: type) -> bool:
    """Whether values of ``cls`` are a device's handle (a position and a velocity, no rotation)."""
    fields = getattr(cls, "__dataclass_fields__", {})
    return "position" in fields and "velocity" in fields


def slot_value(slot: Slot) -> Any:
    """The value a pooled frame holds, read while the slot is held."""
    if isinstance(slot.stamp, MeshInfo):
        return mesh_cloud(TriangleMesh.from_slot(slot))
    raise WrongTypeError(f"a pooled frame of {type(slot.stamp).__name__} has no converter (pooled meshes have)")


def mesh_cloud(mesh: TriangleMesh) -> PointCloud:
    """A mesh's vertices and colours, copied, in its frame, stamped with its image's time."""
    return PointCloud(np.array(mesh.vertices), np.array(mesh.colors), mesh.info.image_stamp, mesh.info.frame_id)


def adapted(value: Any, frame: str) -> Any:
    """``value`` (a port's, or a pooled frame's) as its converter takes it (see the module docstring)."""
    if isinstance(value, Stamped):
        value = value.value
    if isinstance(value, TriangleMesh):
        return mesh_cloud(value)
    if is_handle(type(value)):
        transform = np.eye(4)
        transform[:3, 3] = value.position
        return FramePose(frame, HANDLE, transform)
    return value
