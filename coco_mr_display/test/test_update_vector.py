"""UpdateVector on an arrow GLEntity, drawn by real OpenGL: the arrow starts at the entity's pose,
points along the vector, is as long as the vector times ``scale``, and is hidden until a vector
arrives and while it is shorter than ``min_norm``; a bad vector is refused, counted, and the last
good one stays."""

from __future__ import annotations

import math

import numpy as np
import pytest

from coco_core import Application
from coco_core.component import Component
from coco_core.ports import OutputPort
from coco_core.stamps import Stamped
from coco_core.transforms import se3
from coco_core.transforms.samples import FramePose
from coco_mr_display.entity import GLEntity
from coco_mr_display.mesh import primitive
from coco_mr_display.update_vector import UpdateVector, rotation_to
from test_mesh import camera_view, draw, drawn_mask

SIZE = (200, 200)
FOV = 60.0
DISTANCE = 2.0
"""The camera looks down -z at the plane z = 0 from this far: at the centre a pixel is this many m."""
PIXEL = 2 * DISTANCE * math.tan(math.radians(FOV / 2)) / SIZE[1]
TIP = 4 * PIXEL
"""The cone's last pixels are under a pixel wide and not all rasterised."""


class Force(Component):
    """What HapticRenderer writes for a display: the proxy's pose and the force at it."""

    proxy = OutputPort(FramePose)
    force = OutputPort(tuple)


@pytest.mark.parametrize("direction", [(1, 0, 0), (0, 0, 1), (0, 0, -1), (0.3, -0.5, 0.8)])
def test_rotation_to_takes_z_onto_the_direction(direction):
    unit = np.asarray(direction, float) / np.linalg.norm(direction)
    rotation = rotation_to(unit)
    assert np.allclose(rotation @ [0, 0, 1], unit)
    assert np.allclose(rotation @ rotation.T, np.eye(3)) and np.isclose(np.linalg.det(rotation), 1.0)


def test_arrow_primitive_runs_from_the_origin_along_z():
    arrow = primitive("arrow", [0.01, 0.5])
    assert np.allclose(arrow.bounds, [[-0.02, -0.02, 0.0], [0.02, 0.02, 0.5]])
    with pytest.raises(Exception, match="shaft radius and length"):
        primitive("arrow", [0.01])


@pytest.fixture
def arrow(gl_context, framebuffer):
    """An arrow entity at the proxy with an UpdateVector peer, seen from z = 2 looking down -z; yields
    (the drawn silhouette, the source, the peer)."""
    app = Application("update-vector-test")
    entity = GLEntity("force_arrow", mesh="arrow", size=[0.02, 1.0], color=[0.2, 0.6, 1.0])
    entity.add_peer(UpdateVector("force_vector", scale=0.1, min_norm=0.05))
    source = Force("renderer")
    app.add(entity)
    app.add(source)
    app.connect("renderer.proxy", "force_arrow.pose")
    app.connect("renderer.force", "force_vector.vector")
    assert entity.configure()
    entity.gl_init(gl_context)
    fbo = framebuffer(*SIZE)
    view = camera_view([0, 0, DISTANCE], [0, 0, 0], SIZE, fov_y=FOV)

    def silhouette() -> np.ndarray:
        draw(gl_context, fbo, view, entity)
        return drawn_mask(fbo)

    yield silhouette, source, entity.peers[0]
    entity.gl_release()


def extent_px(mask: np.ndarray) -> tuple[int, int, int, int]:
    """(first column, last column, first row, last row) drawn."""
    rows, columns = np.nonzero(mask)
    return columns.min(), columns.max(), rows.min(), rows.max()


def test_arrow_points_along_the_force_from_the_proxy(arrow):
    silhouette, source, peer = arrow
    assert not silhouette().any(), "no force yet: nothing to show (not a 1 m arrow at the origin)"
    source.proxy.write(FramePose("world", "proxy", se3.make(translation=(-0.3, 0.0, 0.0))))
    source.force.write(Stamped((6.0, 0.0, 0.0)))  # 6 N along +x: 0.6 m from x = -0.3 to 0.3
    left, right, top, bottom = extent_px(silhouette())
    centre_x = SIZE[0] / 2
    assert abs((left - centre_x) * PIXEL + 0.3) < 2 * PIXEL + 0.04, "starts at the proxy (head radius aside)"
    assert abs((right - centre_x) * PIXEL - 0.3) < TIP, "ends 6 N x 0.1 m/N further along x"
    assert (bottom - top) * PIXEL < 0.1, "lies along x, as thick as the head"
    assert peer.stats.latency.count == 1, "the stamped force's latency ends when it is drawn"

    source.force.write((0.0, -3.0, 0.0))  # along -y (down the image): 0.3 m
    left, right, top, bottom = extent_px(silhouette())
    assert abs((bottom - SIZE[1] / 2) * PIXEL - 0.3) < TIP, "0.3 m down the image"
    assert (right - left) * PIXEL < 0.1, "lies along y now"


def test_small_and_bad_forces(arrow):
    silhouette, source, peer = arrow
    source.proxy.write(FramePose("world", "proxy", np.eye(4)))
    source.force.write((2.0, 0.0, 0.0))
    shown = silhouette()
    assert shown.any()
    source.force.write((0.01, 0.0, 0.0))
    assert not silhouette().any(), "out of contact (below min_norm): hidden"
    source.force.write((2.0, 0.0, 0.0))
    assert np.array_equal(silhouette(), shown)
    for bad in ((math.nan, 0.0, 0.0), (1.0, 2.0), "up"):
        source.force.write(bad)
        assert np.array_equal(silhouette(), shown), f"{bad!r} is refused: the last good vector stays"
    assert peer.stats.refused == 3
