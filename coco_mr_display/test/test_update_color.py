"""UpdateColor: colour maps (endpoints, clamping, the teleop app's green-yellow-red mapping, matplotlib's),
and the colour a GLEntity actually draws as the scalar (or a direct colour) changes."""

from __future__ import annotations

import math

import matplotlib
import numpy as np
import pytest

from coco_core import Application
from coco_core.component import Component, UnknownNameError
from coco_core.ports import OutputPort
from coco_core.stamps import Stamped
from coco_mr_display.entity import GLEntity
from coco_mr_display.update_color import UpdateColor, colormap
from test_mesh import camera_view, draw

SIZE = (80, 60)


def test_green_yellow_red_endpoints_and_clamping():
    peer = UpdateColor("map", min=0.02, max=0.5)
    peer.on_config()
    assert peer.map(0.02) == (0.0, 1.0, 0.0, 1.0)
    assert peer.map(0.26) == pytest.approx((1.0, 1.0, 0.0, 1.0))
    assert peer.map(0.5) == (1.0, 0.0, 0.0, 1.0)
    assert peer.map(-3.0) == peer.map(0.02) and peer.map(7.0) == peer.map(0.5)


@pytest.mark.parametrize("s", np.linspace(0.0, 1.0, 11))
def test_green_yellow_red_is_the_update_color_calc_mapping(s):
    """The teleop app's UpdateColorCalc: r = min(1, 2 s), g = min(1, 2 (1 - s)), b = 0."""
    r, g, b, a = colormap("green_yellow_red")(s)
    assert (r, g, b, a) == pytest.approx((min(1.0, 2 * s), min(1.0, 2 * (1 - s)), 0.0, 1.0))


def test_matplotlib_maps_and_unknown_names():
    viridis = colormap("viridis")
    assert viridis(0.0) == pytest.approx(tuple(matplotlib.colormaps["viridis"](0.0)))
    assert viridis(1.0) == pytest.approx(tuple(matplotlib.colormaps["viridis"](1.0)))
    with pytest.raises(UnknownNameError, match=r"unknown colour map 'viridiss'; did you mean 'viridis'\? "
                                               r"valid: .*green_yellow_red.*"):
        colormap("viridiss")
    with pytest.raises(ValueError, match=r"max \(1.0\) must be greater than min \(1.0\)"):
        UpdateColor("flat", min=1.0, max=1.0).on_config()


class Distance(Component):
    """What the teleop app's EndEffectorDistance writes: a Stamped distance and a Stamped colour."""

    distance = OutputPort(Stamped[float])
    color = OutputPort(Stamped[tuple])


@pytest.fixture
def bowl(gl_context, framebuffer):
    """A sphere with an UpdateColor peer fed by a Distance component; returns (draw and read the centre
    pixel, the source, the UpdateColor)."""
    app = Application("update-color-test")
    # Only ambient light: the pixel is exactly the colour drawn.
    sphere = GLEntity("bowl", mesh="sphere", color=[0.5, 0.5, 0.5], position=[0.0, 0.0, -3.0],
                      ambient=1.0, diffuse=0.0, specular=0.0)
    sphere.add_peer(UpdateColor("bowl_color", colormap="green_yellow_red", min=0.02, max=0.5))
    source = Distance("distance")
    app.add(sphere)
    app.add(source)
    app.connect("distance.distance", "bowl_color.value")
    app.connect("distance.color", "bowl_color.color")
    assert sphere.configure()
    sphere.gl_init(gl_context)
    fbo = framebuffer(*SIZE)
    view = camera_view([0, 0, 0], [0, 0, -1], SIZE)

    def centre() -> tuple[int, int, int]:
        return tuple(int(c) for c in draw(gl_context, fbo, view, sphere)[SIZE[1] // 2, SIZE[0] // 2])

    yield centre, source, sphere.peers[0]
    sphere.gl_release()


def test_rendered_colour_follows_the_distance(bowl):
    centre, source, peer = bowl
    assert centre() == (128, 128, 128), "nothing received yet: the entity's own colour"
    expected = {0.0: (0, 255, 0), 0.02: (0, 255, 0), 0.14: (128, 255, 0), 0.26: (255, 255, 0),
                0.38: (255, 128, 0), 0.5: (255, 0, 0), 3.0: (255, 0, 0)}
    for distance, colour in expected.items():
        source.distance.write(Stamped(distance))
        drawn = centre()
        assert np.abs(np.subtract(drawn, colour)).max() <= 1, (distance, drawn, colour)
    assert peer.stats.latency.count == len(expected), "each stamped value's latency ends when it is drawn"
    source.distance.write(Stamped(math.nan))
    assert centre() == (255, 0, 0), "a NaN distance keeps the last colour"
    # No new value: the colour stays.
    assert centre() == (255, 0, 0)


def test_direct_colour_input(bowl):
    centre, source, _ = bowl
    source.color.write(Stamped((0.0, 0.0, 1.0)))
    assert centre() == (0, 0, 255)
    source.distance.write(Stamped(0.02))
    assert centre() == (0, 255, 0), "the newest input wins"
