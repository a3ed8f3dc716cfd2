"""GLEntity renders real frames headless: a box at a known pose covers its analytic projection; colour
and textures show; it follows a graph frame and a pose port; preRender peers change colour, pose and
shape; bad meshes fail with the file named; and it works inside a running GLManager."""

from __future__ import annotations

import logging
import math

import cv2
import numpy as np
import pytest
import trimesh

from conftest import CUBE_CORNERS, project
from coco_core import Application
from coco_core.component import Component
from coco_core.errors import MeshLoadError
from coco_core.operations import operation
from coco_core.ports import InputPort, OutputPort
from coco_core.stamps import Stamped
from coco_core.transforms import se3
from coco_core.transforms.resources import ResourceNotFoundError
from coco_core.transforms.samples import FramePose, TransformSample
from coco_mr_display.draw_state import DrawState
from coco_mr_display.entity import GLEntity
from test_mesh import camera_view, draw, textured_quad

SIZE = (160, 120)


@pytest.fixture
def scene(gl_context, framebuffer):
    """``scene(*entities, view=...)``: configure (in an application, for the graph) and draw one frame."""
    app = Application("entity-test")
    fbo = framebuffer(*SIZE)
    added: list[GLEntity] = []

    def render(*entities: GLEntity, view=None) -> np.ndarray:
        for entity in entities:
            if entity not in added:
                if entity.app is None:
                    app.add(entity)
                assert entity.configure(), f"{entity.name} failed to configure (see the log)"
                entity.gl_init(gl_context)
                added.append(entity)
        return draw(gl_context, fbo, view or camera_view([0, 0, 0], [0, 0, -1], SIZE), *entities)

    render.app = app
    yield render
    for entity in added:
        entity.gl_release()


def mask_of(image: np.ndarray) -> np.ndarray:
    return image.max(axis=2) > 0


def assert_projected_box(mask: np.ndarray, view, model: np.ndarray) -> None:
    """``mask`` is the convex hull of the unit box's 8 corners through ``model`` and ``view``: every
    pixel whose centre is more than a pixel inside the hull is drawn, every one more than a pixel
    outside is not (the outline's own pixels depend on GL's rasterisation rules)."""
    corners = (np.c_[CUBE_CORNERS, np.ones(8)] @ model.T)[:, :3]
    hull = cv2.convexHull(project(view, corners, mask.shape[0]).astype(np.float32))
    area = cv2.contourArea(hull)
    assert area > 400, "the scene should show a sizeable box"
    ys, xs = np.indices(mask.shape)
    for y, x in zip(ys.ravel(), xs.ravel()):
        inside = cv2.pointPolygonTest(hull, (float(x) + 0.5, float(y) + 0.5), True)
        if abs(inside) > 1.0:
            assert mask[y, x] == (inside > 0), f"pixel {x},{y} is {inside:.1f} px from the outline"


def test_box_at_known_pose_covers_its_projection(scene):
    rpy, position = [0.4, -0.6, 0.3], [0.3, -0.2, -4.0]
    box = GLEntity("box", mesh="box", position=position, rpy=rpy, scale=[1.2, 0.8, 1.0])
    view = camera_view([0, 0, 0], [0, 0, -1], SIZE)
    image = scene(box, view=view)
    model = se3.make(se3.rpy_to_matrix(*rpy), position) @ np.diag([1.2, 0.8, 1.0, 1.0])
    assert_projected_box(mask_of(image), view, model)
    # The same pose as a quaternion draws the same pixels.
    turned = GLEntity("turned", position=position, scale=[1.2, 0.8, 1.0],
                      quaternion=se3.matrix_to_quaternion(se3.rpy_to_matrix(*rpy)).tolist())
    assert (mask_of(scene(turned, view=view)) == mask_of(image)).mean() > 0.999


def test_color_and_mesh_colours(scene, tmp_path):
    """``color`` paints a mesh without colour (a primitive, an STL file); a mesh's own colours win over it."""
    plain = GLEntity("plain", mesh="sphere", color=[0.0, 0.0, 1.0], position=[0, 0, -3], specular=0.0)
    pixel = scene(plain)[SIZE[1] // 2, SIZE[0] // 2]
    assert pixel[2] > 150 and pixel[0] == 0 and pixel[1] == 0
    stl = tmp_path / "box.stl"
    trimesh.creation.box(extents=(1, 1, 1)).export(stl)
    pixel = scene(GLEntity("stl", mesh=str(stl), color=[1.0, 1.0, 0.0], position=[0, 0, -3], specular=0.0))[
        SIZE[1] // 2, SIZE[0] // 2]
    assert pixel[0] > 150 and pixel[1] > 150 and pixel[2] == 0
    coloured = trimesh.creation.box(extents=(1, 1, 1))
    coloured.visual.face_colors = (0, 255, 0, 255)
    path = tmp_path / "green_box.ply"
    coloured.export(path)
    own = GLEntity("own", mesh=str(path), color=[1.0, 0.0, 0.0], position=[0, 0, -3], specular=0.0)
    pixel = scene(own)[SIZE[1] // 2, SIZE[0] // 2]
    assert pixel[1] > 150 and pixel[0] == 0 and pixel[2] == 0


@pytest.mark.parametrize("fmt", ["glb", "obj"])
def test_texture_shows(scene, tmp_path, fmt):
    """A textured square (GLB, or OBJ + MTL + PNG written by trimesh) seen face-on shows its four quadrants
    where they are in the image: red top-left, blue top-right, green bottom-left, yellow bottom-right."""
    path = tmp_path / f"quad.{fmt}"
    textured_quad().export(path)
    quad = GLEntity("quad", mesh=str(path), position=[0, 0, -2.5], specular=0.0, ambient=1.0, diffuse=0.0)
    image = scene(quad)
    mask = mask_of(image)
    ys, xs = np.nonzero(mask)
    top, bottom, left, right = ys.min(), ys.max(), xs.min(), xs.max()
    quarter_x, quarter_y = (right - left) // 4, (bottom - top) // 4
    samples = {"top-left": image[top + quarter_y, left + quarter_x],
               "top-right": image[top + quarter_y, right - quarter_x],
               "bottom-left": image[bottom - quarter_y, left + quarter_x],
               "bottom-right": image[bottom - quarter_y, right - quarter_x]}
    expected = {"top-left": (255, 0, 0), "top-right": (0, 0, 255), "bottom-left": (0, 255, 0),
                "bottom-right": (255, 255, 0)}
    for where, colour in expected.items():
        assert np.abs(samples[where].astype(int) - colour).max() <= 8, (where, samples[where])


def test_back_face_culling(scene, tmp_path):
    """A closed box looks the same culled; a single-sided square seen from behind disappears."""
    view = camera_view([0, 0, 0], [0, 0, -1], SIZE)
    pose = dict(position=[0.2, 0.1, -4.0], rpy=[0.5, 0.4, 0.3])
    drawn = mask_of(scene(GLEntity("both_sides", **pose), view=view))
    culled = mask_of(scene(GLEntity("front_sides", cull_back_faces=True, **pose), view=view))
    assert drawn.sum() > 400 and (drawn == culled).all()
    path = tmp_path / "square.ply"
    trimesh.Trimesh([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], [[0, 1, 2], [0, 2, 3]]).export(path)
    behind = dict(mesh=str(path), position=[0.0, 0.0, -4.0], rpy=[0.0, math.pi, 0.0])  # its front faces away
    assert mask_of(scene(GLEntity("square", **behind), view=view)).sum() > 400
    assert not mask_of(scene(GLEntity("culled_square", cull_back_faces=True, **behind), view=view)).any()
    # Mirrored (scale -1 along x), the square facing the camera is still seen from its front.
    mirrored = GLEntity("mirrored_square", mesh=str(path), position=[0.0, 0.0, -4.0], scale=[-1.0, 1.0, 1.0],
                        cull_back_faces=True)
    assert mask_of(scene(mirrored, view=view)).sum() > 400


def test_follows_a_graph_frame(scene):
    app = scene.app
    view = camera_view([0, 0, 0], [0, 0, -1], SIZE)
    marker = se3.make(se3.rpy_to_matrix(0.3, 0.2, 0.1), [-1.0, 0.0, -4.0])
    app.transforms.set_transform("world", "marker", marker)
    box = GLEntity("tracked", frame="marker")
    assert_projected_box(mask_of(scene(box, view=view)), view, marker)
    marker = se3.make(se3.rpy_to_matrix(0.0, 0.0, math.pi / 2), [1.0, 0.5, -5.0])
    app.transforms.set_transform("world", "marker", marker)
    assert_projected_box(mask_of(scene(box, view=view)), view, marker)
    # An offset from the attributes applies in the frame's axes: the marker's x is the world's y.
    box.set_attribute_now("position", [1.0, 0.0, 0.0])
    assert_projected_box(mask_of(scene(box, view=view)), view, marker @ se3.make(translation=[1.0, 0.0, 0.0]))


def test_a_frame_whose_edge_has_no_sample_yet_is_not_drawn_until_it_has(scene, caplog):
    """A frame joined to the world by a dynamic edge that has had no value yet (a tracker declared in
    the file that has not sent a pose): no error, nothing drawn, then drawn at the first value."""
    app = scene.app
    view = camera_view([0, 0, 0], [0, 0, -1], SIZE)
    app.transforms.add_static("world", "tracker", se3.make(translation=[0.0, 0.0, -4.0]))
    app.transforms.add_dynamic("tracker", "hand")
    box = GLEntity("hand_model", frame="hand")
    with caplog.at_level(logging.WARNING):
        assert not mask_of(scene(box, view=view)).any()
    assert box.enabled and box.stats.errors == 0, "waiting for a pose is not an error"
    assert "not drawn until" in caplog.text
    app.transforms.set_transform("tracker", "hand", np.eye(4), stamp=1.0)
    assert_projected_box(mask_of(scene(box, view=view)), view, se3.make(translation=[0.0, 0.0, -4.0]))


class PoseSource(Component):
    out = OutputPort(object)


def test_follows_the_pose_port(scene):
    app = scene.app
    source = app.add(PoseSource("source"))
    box = GLEntity("posed")
    app.add(box)
    app.connect("source.out", "posed.pose")
    view = camera_view([0, 0, 0], [0, 0, -1], SIZE)

    def drawn_at(value, expected: np.ndarray) -> None:
        if value is not None:
            source.out.write(value)
        assert_projected_box(mask_of(scene(box, view=view)), view, expected)

    pose = se3.make(se3.rpy_to_matrix(0.2, 0.0, 0.4), [1.0, 0.0, -4.0])
    drawn_at(pose, pose)
    pose = se3.make(translation=[0.0, -1.0, -5.0])
    drawn_at(FramePose("world", "posed", pose), pose)
    # A sample in another frame goes through the graph.
    table = se3.make(se3.rpy_to_matrix(0.0, 0.0, math.pi / 2), [-1.0, 0.0, -4.0])
    app.transforms.set_transform("world", "table", table)
    pose = se3.make(translation=[0.0, 1.0, 0.0])
    drawn_at(Stamped(TransformSample("table", "posed", pose)), table @ pose)
    drawn_at(None, table @ pose)  # no new value: the last one stays


class Reshape(Component):
    """A preRender peer: stretches the entity's vertices along x, moves and recolours it."""

    def init(self) -> None:
        self.stretch = 1.0
        self.shift = 0.0
        self.calls = 0

    @operation(name="preRender")
    def pre_render(self, state: DrawState) -> None:
        self.calls += 1
        if self.stretch != 1.0:
            state.set_vertices(state.vertices * [self.stretch, 1.0, 1.0])
        state.pose = se3.make(translation=[self.shift, 0.0, 0.0]) @ state.pose
        state.set_color((1.0, 0.0, 1.0), override=False)


def test_pre_render_peer_changes_shape_pose_and_colour(scene):
    box = GLEntity("shaped", position=[0, 0, -4.0], specular=0.0)
    peer = box.add_peer(Reshape("reshape"))
    view = camera_view([0, 0, 0], [0, 0, -1], SIZE)
    before = mask_of(scene(box, view=view))
    assert peer.calls == 1
    width_before = np.ptp(np.nonzero(before)[1])
    peer.stretch = 2.0
    image = scene(box, view=view)
    after = mask_of(image)
    width_after = np.ptp(np.nonzero(after)[1])
    assert 1.9 < (width_after + 1) / (width_before + 1) < 2.1, (width_before, width_after)
    assert np.ptp(np.nonzero(after)[0]) == np.ptp(np.nonzero(before)[0]), "only x was stretched"
    pixel = image[SIZE[1] // 2, SIZE[0] // 2]
    assert pixel[0] > 150 and pixel[2] > 150 and pixel[1] == 0, "the peer's colour is drawn"
    peer.stretch, peer.shift = 1.0, 1.0
    assert_projected_box(mask_of(scene(box, view=view)), view, se3.make(translation=[1.0, 0.0, -4.0]))
    # A peer that stops changing the shape leaves the entity as its attributes describe it.
    peer.shift = 0.0
    assert (mask_of(scene(box, view=view)) == before).all()
    # A new topology: a single triangle instead of the box.

    class Triangle(Component):
        @operation(name="preRender")
        def pre_render(self, state: DrawState) -> None:
            state.set_vertices([[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.0, 0.5, 0.0]], faces=[[0, 1, 2]])

    triangle = GLEntity("triangle", position=[0, 0, -4.0])
    triangle.add_peer(Triangle("triangle_shape"))
    triangle_mask = mask_of(scene(triangle, view=view))
    corners = project(view, np.array([[-0.5, -0.5, -4.0], [0.5, -0.5, -4.0], [0.0, 0.5, -4.0]]), SIZE[1])
    expected = np.zeros(triangle_mask.shape, np.uint8)
    cv2.fillPoly(expected, [np.round(corners - 0.5).astype(np.int32)], 1)
    assert np.logical_xor(triangle_mask, expected.astype(bool)).sum() < 0.1 * expected.sum()


def test_bad_meshes_fail_with_the_file_named(tmp_path):
    missing = GLEntity("missing", mesh=str(tmp_path / "nowhere.obj"))
    with pytest.raises(ResourceNotFoundError, match=r"nowhere\.obj does not exist"):
        missing.on_config()
    assert not missing.configure(), "a failing on_config disables the component instead of raising"
    with pytest.raises(ResourceNotFoundError, match=r"package 'no_such_package' not found; tried"):
        GLEntity("url", mesh="package://no_such_package/meshes/a.stl").on_config()
    with pytest.raises(MeshLoadError, match=r"a box takes size = x y z extents"):
        GLEntity("sized", mesh="box", size=[1.0, 2.0]).on_config()
    with pytest.raises(ValueError, match=r"rpy or as quaternion, not both"):
        GLEntity("both", rpy=[0.1, 0, 0], quaternion=[0, 0, 0, 1]).on_config()
    with pytest.raises(ValueError, match=r"expected r g b or r g b a in 0..1"):
        GLEntity("colour", color=[2.0, 0.0, 0.0])


def test_bad_pose_input_is_reported_and_the_entity_keeps_drawing(scene, caplog):
    app = scene.app
    source = app.add(PoseSource("bad_source"))
    box = GLEntity("robust", position=[0, 0, -4.0])
    app.add(box)
    app.connect("bad_source.out", "robust.pose")
    source.out.write("not a pose")
    image = scene(box)
    assert "FramePose, a TransformSample or a 4x4" in caplog.text
    assert mask_of(image).sum() > 0, "the previous state (its attributes) is still drawn"


class Scalar(Component):
    distance = OutputPort(float)


class Frames(Component):
    image = InputPort(object)


def test_inside_a_gl_manager():
    """Through GLManager: it steps the entity, which steps its UpdateColor peer before preRender."""
    from coco_mr_display.camera import GLCameraManager
    from coco_mr_display.manager import GLManager
    from coco_mr_display.update_color import UpdateColor

    app = Application("entity-in-manager")
    manager = GLManager("display", width=SIZE[0], height=SIZE[1])
    manager.add_peer(GLCameraManager("camera", position=[0.0, -4.0, 0.0], look_at=[0.0, 0.0, 0.0]))
    bowl = manager.add_peer(GLEntity("bowl", mesh="sphere", specular=0.0))
    bowl.add_peer(UpdateColor("bowl_color", min=0.0, max=1.0))
    source, frames = Scalar("distance_source"), Frames("frames")
    for component in (manager, source, frames):
        app.add(component)
    app.connect("distance_source.distance", "bowl_color.value")
    app.connect("display.color", "frames.image")
    assert manager.configure(), "GLManager failed to configure (see the log)"
    try:
        centres = []
        for distance in (0.0, 1.0):
            source.distance.write(distance)
            manager.step()
            centres.append(frames.image.read()[1].data[SIZE[1] // 2, SIZE[0] // 2])
    finally:
        manager.stop()
    assert bowl.enabled
    green, red = centres
    assert green[1] > 150 and green[0] == 0 and green[2] == 0, f"distance 0 is green: {green}"
    assert red[0] > 150 and red[1] == 0 and red[2] == 0, f"distance 1 is red: {red}"


@pytest.mark.parametrize("fmt", ["obj", "stl", "ply", "dae", "glb"])
def test_every_mesh_format_draws_the_same_box(scene, tmp_path, fmt):
    """The unit box written by trimesh in each format the issue names (DAE through pycollada, as
    Baxter's meshes) covers its analytic projection. It is grey, since trimesh writes a colourless
    mesh to DAE with a black material, which would be drawn black."""
    path = tmp_path / f"box.{fmt}"
    box = trimesh.creation.box(extents=(1, 1, 1))
    box.visual.face_colors = (200, 200, 200, 255)
    box.export(path)
    pose = dict(position=[0.2, -0.1, -4.0], rpy=[0.5, -0.4, 0.2])
    view = camera_view([0, 0, 0], [0, 0, -1], SIZE)
    from_file = mask_of(scene(GLEntity(f"file_{fmt}", mesh=str(path), color=[1, 1, 1], **pose), view=view))
    model = se3.make(se3.rpy_to_matrix(*pose["rpy"]), pose["position"])
    assert_projected_box(from_file, view, model)
