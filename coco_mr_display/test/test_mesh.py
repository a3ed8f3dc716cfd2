"""The mesh module: trimesh geometry -> parts (transforms, colours, textures, merging), primitives, load
errors, and the flat-normal Phong program's shading checked against the formula.

Also home of :func:`draw` and :func:`camera_view`, the one-frame helpers the entity, UpdateColor and
URDF tests share (they drive peers exactly as GLManager does: step, then render per view).
"""

from __future__ import annotations

import math

import moderngl
import numpy as np
import pytest
import trimesh
from PIL import Image as PILImage

from conftest import read_rgb
from coco_core.errors import MeshLoadError
from coco_core.transforms import se3
from coco_core.transforms.resources import ResourceNotFoundError
from coco_mr_display import projection as proj
from coco_mr_display.mesh import load_geometry, load_parts, merge_parts, parts_of, primitive
from coco_mr_display.peer import GLPeer
from coco_mr_display.view import RenderView

BAXTER_MESH = "package://example-robot-data/robots/baxter_description/meshes/upper_shoulder/S0.DAE"


def camera_view(eye: list[float], target: list[float], size: tuple[int, int], up: tuple[float, ...] = (0, 1, 0),
                fov_y: float = 60.0, frame: str = "world") -> RenderView:
    """The view of a perspective camera at ``eye`` looking at ``target``."""
    width, height = size
    return RenderView(se3.inverse(proj.look_at(eye, target, up)), proj.perspective(fov_y, width / height, 0.1, 100.0),
                      (0, 0, width, height), frame=frame)


def draw(ctx: moderngl.Context, fbo: moderngl.Framebuffer, view: RenderView, *peers: GLPeer) -> np.ndarray:
    """One frame as GLManager draws it: clear, ``step()`` every peer, render each; RGB, top row first."""
    fbo.use()
    fbo.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
    for peer in peers:
        peer.step()
    for peer in peers:
        ctx.enable_only(moderngl.DEPTH_TEST)
        peer.render(ctx, view)
    return read_rgb(fbo)


def drawn_mask(fbo: moderngl.Framebuffer) -> np.ndarray:
    """Where the last frame drew anything (depth nearer than the far plane), top row first: the
    silhouette whatever the colours (some of Baxter's parts are black)."""
    width, height = fbo.size
    depth = np.frombuffer(fbo.read(components=1, attachment=-1, dtype="f4", alignment=1), np.float32).reshape(height, width)
    return depth[::-1] < 1.0


def textured_quad(size: int = 64) -> trimesh.Trimesh:
    """A 2 x 2 square in the z = 0 plane whose texture has four coloured quadrants: red top-left, blue
    top-right, green bottom-left, yellow bottom-right (as the image is seen, top row first)."""
    image = np.zeros((size, size, 3), np.uint8)
    half = size // 2
    image[:half, :half] = (255, 0, 0)
    image[:half, half:] = (0, 0, 255)
    image[half:, :half] = (0, 255, 0)
    image[half:, half:] = (255, 255, 0)
    vertices = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    visual = trimesh.visual.TextureVisuals(uv=uv, image=PILImage.fromarray(image))
    return trimesh.Trimesh(vertices, [[0, 1, 2], [0, 2, 3]], visual=visual, process=False)


# --- CPU side ---------------------------------------------------------------------------------------
def test_parts_apply_scene_transforms_then_transform_and_scale():
    box = primitive("box", [1.0, 2.0, 3.0])
    scene = trimesh.Scene()
    scene.add_geometry(box, transform=se3.make(translation=[10.0, 0.0, 0.0]))
    transform = se3.make(se3.rpy_to_matrix(0.0, 0.0, math.pi / 2), [0.0, 0.0, 1.0])
    [part] = parts_of(scene, transform, scale=[2.0, 2.0, 2.0])
    expected = (np.c_[box.vertices + [10.0, 0.0, 0.0], np.ones(8)] @ (transform @ np.diag([2, 2, 2, 1.0])).T)[:, :3]
    np.testing.assert_allclose(part.positions, expected, atol=1e-5)
    assert part.positions.dtype == np.float32 and part.indices.dtype == np.uint32
    assert part.colors is None, "a mesh without colour leaves the colour to its owner"
    [baked] = parts_of(box, color=(1.0, 0.5, 0.0))
    assert baked.colors.tolist() == [[255, 128, 0, 255]] * 8


def test_mirroring_keeps_triangles_wound_outwards():
    box = primitive("box")
    [part] = parts_of(box, scale=[-1.0, 1.0, 1.0])
    triangles = part.positions[part.indices].astype(float)
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    assert (np.einsum("ij,ij->i", normals, triangles.mean(axis=1)) > 0).all(), "normals point away from the centre"


def test_face_colours_stay_per_face():
    box = primitive("box")
    box.visual.face_colors = np.array([[20 * index, 0, 255 - 20 * index, 255] for index in range(12)], np.uint8)
    [part] = parts_of(box)
    corners = part.colors[part.indices]  # (faces, 3 corners, RGBA)
    assert (corners == box.visual.face_colors[:, None, :]).all(), "every corner has its own face's colour"
    np.testing.assert_allclose(part.positions[part.indices], box.vertices[box.faces], atol=1e-6)


def test_repeated_vertices_are_welded_unless_their_colours_differ():
    """A mesh that repeats its vertices per face (as DAE and STL files do) is drawn with each distinct
    vertex once; vertices of one position but different colours stay apart."""
    sphere = primitive("sphere", [1.0])
    unwelded = trimesh.Trimesh(sphere.vertices[sphere.faces].reshape(-1, 3),
                               np.arange(3 * len(sphere.faces)).reshape(-1, 3), process=False)
    [part] = parts_of(unwelded, color=(0.2, 0.4, 0.6))
    assert len(part.positions) == len(sphere.vertices) and part.triangles == len(sphere.faces)
    np.testing.assert_array_equal(part.positions[part.indices], unwelded.vertices[unwelded.faces].astype("f4"))
    box = primitive("box")
    box.visual.face_colors = np.repeat([[255, 0, 0, 255], [0, 255, 0, 255], [0, 0, 255, 255]], 4, axis=0)
    [coloured] = parts_of(box)
    corners = {(vertex, tuple(colour)) for face, colour in zip(box.faces, box.visual.face_colors) for vertex in face}
    assert len(coloured.positions) == len(corners) < 3 * len(box.faces), "one vertex per corner and colour"
    assert (coloured.colors[coloured.indices] == box.visual.face_colors[:, None, :]).all()


def test_merge_keeps_one_part_per_kind():
    red = primitive("box")
    red.visual.face_colors = (255, 0, 0, 255)
    plain = [primitive("sphere"), primitive("cylinder")]
    parts = parts_of(red) + [part for shape in plain for part in parts_of(shape)] + parts_of(textured_quad())
    merged = merge_parts(parts)
    assert len(merged) == 3  # the textured quad, the coloured box, the two plain shapes together
    textured, coloured, uncoloured = merged
    assert textured.texture is not None and textured.uvs is not None
    assert coloured.colors is not None and (coloured.colors[:, :3] == (255, 0, 0)).all()
    assert uncoloured.colors is None
    assert uncoloured.triangles == sum(len(shape.faces) for shape in plain)
    # Indices of the second merged shape point at its own vertices.
    sphere_vertices = len(plain[0].vertices)
    np.testing.assert_allclose(uncoloured.positions[uncoloured.indices[len(plain[0].faces):]],
                               plain[1].vertices[plain[1].faces].astype("f4"), atol=1e-6)
    assert uncoloured.indices[len(plain[0].faces):].min() == sphere_vertices


def test_texture_rows_go_bottom_first():
    [part] = parts_of(textured_quad())
    assert tuple(part.texture[0, 0, :3]) == (0, 255, 0), "row 0 of a GL texture is the image's bottom row"
    assert tuple(part.texture[-1, 0, :3]) == (255, 0, 0)


def test_subdivide_quadruples_triangles():
    [part] = parts_of(primitive("box"), subdivide=2)
    assert part.triangles == 12 * 16


def test_simplify_keeps_the_shape_and_its_colour():
    pytest.importorskip("fast_simplification")
    sphere = primitive("sphere", [1.0])
    unmerged = trimesh.Trimesh(sphere.vertices[sphere.faces].reshape(-1, 3),
                               np.arange(3 * len(sphere.faces)).reshape(-1, 3), process=False)
    unmerged.visual.face_colors = (10, 20, 30, 255)  # one colour: it may be simplified
    [part] = parts_of(unmerged, keep=0.25)
    assert 0.2 * len(sphere.faces) <= part.triangles <= 0.3 * len(sphere.faces), part.triangles
    radii = np.linalg.norm(part.positions, axis=1)
    assert np.abs(radii - 1.0).max() < 0.05, "the simplified sphere is still the unit sphere"
    assert (part.colors == (10, 20, 30, 255)).all() and len(part.colors) == len(part.positions)
    odd = (np.arange(len(sphere.faces)) % 2).astype(bool)[:, None]
    unmerged.visual.face_colors = np.where(odd, (255, 0, 0, 255), (0, 0, 255, 255)).astype(np.uint8)
    [whole] = parts_of(unmerged, keep=0.25)
    assert whole.triangles == len(sphere.faces), "a mesh of several colours is kept whole"


def test_primitive_sizes_and_errors():
    assert np.allclose(primitive("box", [1, 2, 3]).extents, [1, 2, 3])
    assert np.isclose(np.linalg.norm(primitive("sphere", [2.0]).vertices, axis=1).max(), 2.0)
    assert np.allclose(primitive("cylinder", [0.5, 4.0]).extents[2], 4.0)
    with pytest.raises(MeshLoadError, match=r"sphere takes size = a radius"):
        primitive("sphere", [1.0, 2.0])
    with pytest.raises(MeshLoadError, match=r"unknown primitive 'cone'; valid: box, sphere, cylinder"):
        primitive("cone")


def test_load_errors_name_the_file(tmp_path):
    with pytest.raises(ResourceNotFoundError, match=r"missing\.stl does not exist"):
        load_geometry(tmp_path / "missing.stl")
    garbage = tmp_path / "garbage.stl"
    garbage.write_bytes(b"not a mesh at all")
    with pytest.raises(MeshLoadError, match=r"garbage\.stl holds no triangles"):
        load_parts(garbage)
    unknown = tmp_path / "notes.xyz123"
    unknown.write_text("1 2 3")
    with pytest.raises(MeshLoadError, match=r"cannot load mesh .*notes\.xyz123.*trimesh reads: .*obj.*stl"):
        load_geometry(unknown)


def test_package_url_mesh_loads_with_its_colours():
    pytest.importorskip("collada", reason="DAE meshes need pycollada")
    try:
        parts = load_parts(BAXTER_MESH)
    except ResourceNotFoundError as error:
        pytest.skip(f"example-robot-data is not installed: {error}")
    assert sum(part.triangles for part in parts) > 30_000
    assert all(part.colors is not None for part in parts), "the DAE's materials give every part a colour"


# --- GPU side: the flat-normal Phong shading --------------------------------------------------------
def test_flat_shading_matches_phong_formula(gl_context, framebuffer):
    """Two faces of a box seen at 45 degrees: each pixel is ``colour * (ambient + diffuse * n.l)``
    with the face's own normal, whatever the (shared, unnormalled) vertices say."""
    from coco_mr_display.entity import GLEntity

    width, height = 200, 150
    fbo = framebuffer(width, height)
    light = np.array([0.0, 0.0, 1.0])
    box = GLEntity("box", mesh="box", color=[1.0, 1.0, 1.0], rpy=[0.0, math.pi / 4, 0.0], specular=0.0,
                   ambient=0.2, diffuse=0.8, light=light.tolist())
    box.configure()
    box.gl_init(gl_context)
    # Camera on +z, looking at the box turned 45 degrees about y: faces +x and +z, each 45 degrees off.
    image = draw(gl_context, fbo, camera_view([0, 0, 4], [0, 0, 0], (width, height)), box)
    expected = 255 * (0.2 + 0.8 * math.cos(math.pi / 4))
    left, right = image[height // 2, width // 2 - 12], image[height // 2, width // 2 + 12]
    assert abs(int(left[0]) - expected) <= 2 and abs(int(right[0]) - expected) <= 2, (left, right, expected)
    # Tilt the light towards +x: the face turned towards +x gets brighter than the other.
    box.set_attribute_now("light", [1.0, 0.0, 1.0])
    image = draw(gl_context, fbo, camera_view([0, 0, 4], [0, 0, 0], (width, height)), box)
    left, right = image[height // 2, width // 2 - 12], image[height // 2, width // 2 + 12]
    assert abs(int(right[0]) - 255) <= 2, "the +x face faces the light: ambient + full diffuse"
    assert abs(int(left[0]) - 255 * 0.2) <= 2, "the other face is at 90 degrees from it: ambient only"
    box.gl_release()
