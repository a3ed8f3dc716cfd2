"""GLUrdf: a robot drawn from its URDF's visual meshes, every link posed from the transformation graph.

The kinematics are not computed here: a TransformationInterface (or anything else) loads the same
URDF into the application's graph with the same ``prefix`` and writes the joint values; GLUrdf looks
up ``T_world_link`` of each link once per view (the graph caches paths and values, and Pinocchio
computes all placements in one pass per joint update).

Loading is split so that errors are immediate and the render loop never waits:

- ``on_config`` (fast, synchronous): parse the URDF, resolve every mesh file (a missing one fails
  here, named), check the ``colors`` link names against the URDF's links;
- a loader thread started there reads the meshes (DAE, STL, OBJ ... through trimesh; each file
  once, even when several links use it), applies visual origins and scales and bakes colours, and
  merges all visuals of a link into as few buffers as possible (one for Baxter's links);
- ``render`` draws nothing until the loader is done, then uploads once and draws each link with one
  draw call per merged part.

Colour of a visual: the mesh's own colours when it has some (DAE materials, vertex colours,
textures), else its URDF material, else the ``color`` attribute. ``colors`` overrides whole links.
Alpha is kept in the colours but drawn opaque (no sorting, no blending: performance first).

Speed on a CPU renderer is per triangle: back faces are culled by default (as RViz does), and
``simplify`` decimates the meshes at load (640x480 on llvmpipe, GLManager frame: Baxter's 412k
triangles 27 fps unculled, 41 fps culled; ``simplify=0.25`` 103k triangles, 129 fps).
"""

from __future__ import annotations

import io
import logging
import threading
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from coco_core.attributes import Attribute
from coco_core.component import UnknownNameError
from coco_core.errors import AttributeValueError, CocoError, did_you_mean
from coco_core.files import URDF_LIMIT, FileReadError, read_regular_file
from coco_core.transforms.graph import KinematicModel
from coco_core.transforms.resources import resolve

from .mesh import GpuMesh, MeshPart, color_problem, load_geometry, merge_parts, parts_of, primitive
from .phong import PhongPeer
from .shown import ShownInputs

if TYPE_CHECKING:
    import moderngl

    from .view import RenderView

log = logging.getLogger("coco.display")


def parse_link_colors(text: str) -> dict[str, tuple[float, float, float, float]]:
    """``"link=r g b [a], other=r g b"`` -> {link: RGBA}; a clear error for anything else."""
    colors: dict[str, tuple[float, float, float, float]] = {}
    for entry in (item.strip() for item in text.split(",")):
        if not entry:
            continue
        link, equals, values = entry.partition("=")
        try:
            numbers = [float(value) for value in values.split()]
        except ValueError:
            numbers = []
        if not (equals and link.strip() and len(numbers) in (3, 4) and all(0.0 <= x <= 1.0 for x in numbers)):
            raise AttributeValueError(f"colour override {entry!r} must look like link=r g b [a] (0..1), "
                                      "entries separated by commas")
        colors[link.strip()] = (numbers[0], numbers[1], numbers[2], numbers[3] if len(numbers) == 4 else 1.0)
    return colors


def _colors_check(text: str) -> str | None:
    try:
        parse_link_colors(text)
    except ValueError as error:
        return str(error)
    return None


@dataclass(frozen=True)
class Visual:
    """One ``<visual>`` of a link, its mesh file resolved (or a primitive)."""

    link: str
    origin: np.ndarray
    shape: str
    """``mesh``, ``box``, ``sphere`` or ``cylinder``."""
    path: Path | None = None
    size: tuple[float, ...] = ()
    scale: tuple[float, ...] | None = None
    color: tuple[float, ...] | None = None
    """The URDF material's RGBA, when it gives one."""


def read_visuals(path: Path) -> tuple[list[str], list[Visual]]:
    """(every link name, every visual) of a URDF file, mesh files resolved relative to it."""
    import yourdfpy

    try:
        data = read_regular_file(path, URDF_LIMIT, "URDF")
    except FileReadError as error:
        raise CocoError(str(error)) from None
    try:
        robot = yourdfpy.URDF.load(io.BytesIO(data), load_meshes=False, build_scene_graph=False,
                                   build_collision_scene_graph=False, load_collision_meshes=False).robot
    except Exception as error:  # yourdfpy raises lxml and ValueError/AttributeError on bad files
        raise CocoError(f"cannot read URDF {path}: {type(error).__name__}: {error}") from None
    named = {material.name: material.color.rgba for material in robot.materials if material.color is not None}
    visuals = []
    for link in robot.links:
        for visual in link.visuals:
            origin = np.eye(4) if visual.origin is None else np.asarray(visual.origin, dtype=float)
            material = visual.material
            color = None
            if material is not None:
                rgba = material.color.rgba if material.color is not None else named.get(material.name)
                color = tuple(float(x) for x in rgba) if rgba is not None else None
            geometry = visual.geometry
            if geometry.mesh is not None:
                scale = geometry.mesh.scale
                visuals.append(Visual(link.name, origin, "mesh", resolve(geometry.mesh.filename, path.parent),
                                      scale=None if scale is None else tuple(np.broadcast_to(scale, 3).tolist()),
                                      color=color))
            elif geometry.box is not None:
                visuals.append(Visual(link.name, origin, "box", size=tuple(geometry.box.size), color=color))
            elif geometry.sphere is not None:
                visuals.append(Visual(link.name, origin, "sphere", size=(geometry.sphere.radius,), color=color))
            elif geometry.cylinder is not None:
                visuals.append(Visual(link.name, origin, "cylinder", color=color,
                                      size=(geometry.cylinder.radius, geometry.cylinder.length)))
    return [link.name for link in robot.links], visuals


def load_links(visuals: list[Visual], default_color: tuple[float, ...], keep: float,
               cancelled: threading.Event) -> dict[str, list[MeshPart]]:
    """The merged parts of every link with visuals (the loader thread's work)."""
    files: dict[Path, Any] = {}
    parts: dict[str, list[MeshPart]] = {}
    for visual in visuals:
        if cancelled.is_set():
            break
        color = visual.color or default_color
        if visual.shape == "mesh":
            assert visual.path is not None
            if visual.path not in files:
                files[visual.path] = load_geometry(visual.path)
            new = parts_of(files[visual.path], visual.origin, visual.scale, color, keep=keep, label=str(visual.path))
        else:
            new = parts_of(primitive(visual.shape, visual.size), visual.origin, color=color, keep=keep,
                           label=visual.shape)
        parts.setdefault(visual.link, []).extend(new)
    return {link: merge_parts(link_parts) for link, link_parts in parts.items()}


@dataclass
class _Link:
    frame: str
    meshes: list[GpuMesh]
    color: tuple[float, ...] | None
    """Override colour, or None for the meshes' own."""


class GLUrdf(PhongPeer):
    """A URDF robot's visual meshes, each link at its transformation-graph pose."""

    urdf = Attribute(str, "", "URDF file or package:// URL")
    prefix = Attribute(str, "", "frame prefix of the robot's links in the graph (as TransformationInterface's)")
    color = Attribute(list[float], [0.6, 0.6, 0.6], "r g b [a] for visuals with no colour in mesh or URDF",
                      check=color_problem)
    colors = Attribute(str, "", "per-link colour overrides: 'link=r g b [a], other=r g b'", check=_colors_check)
    simplify = Attribute(float, 1.0, "fraction of the triangles kept at load (quadric decimation of each "
                         "single-coloured mesh; 1: all; 0.25 draws Baxter 2.5x faster, nearly the same at 640x480)",
                         min=0.01, max=1.0)
    cull_back_faces = Attribute(bool, True, "skip triangles facing away, as RViz does: robot meshes are closed "
                                "and wound outwards; draws Baxter 1.6x faster")
    wait_for_joints = Attribute(bool, False, "draw no link that a robot model places before that model's first "
                                "joint state (the all-zero pose loaded at start is not the robot's), as "
                                "TransformationInterface's attribute of that name publishes nothing then")
    preload = Attribute(bool, False, "read the meshes while the application is built (init), so that the first "
                        "frame shows the robot; the start waits for them (about 2 s for Baxter)")

    def init(self) -> None:
        self.shown = ShownInputs()
        """The origins of the joint states the next frame shows first (the graph's ``origin`` on the robot)."""
        self._links: list[_Link] | None = None
        self._missing: set[str] = set()
        self._cancel = threading.Event()
        self._loading: Future = Future()
        if self.preload:
            self._load(*self._visuals())
            self._loading.result()  # a bad mesh fails the application's construction, with its message

    def on_config(self) -> None:
        if not self.preload:
            threading.Thread(target=self._load, args=self._visuals(), name=f"{self.name}-loader",
                             daemon=True).start()

    def _visuals(self) -> tuple[list[Visual], tuple[float, ...], float]:
        """The URDF's visuals, checked, with the default colour and the fraction kept: what _load needs."""
        if not self.urdf:
            raise CocoError(f"{self.name}: the urdf attribute is empty; give a URDF file or package:// URL")
        path = resolve(self.urdf)
        links, visuals = read_visuals(path)
        overrides = parse_link_colors(self.colors)
        for link in overrides:
            if link not in links:
                raise UnknownNameError(f"{self.name}: colors names link {link!r}, which {path.name} does not "
                                       f"have; {did_you_mean(link, links)}")
        self._overrides = overrides
        default = tuple(self.color) + ((1.0,) if len(self.color) == 3 else ())
        return visuals, default, self.simplify

    def _load(self, visuals: list[Visual], default: tuple[float, ...], keep: float) -> None:
        try:
            self._loading.set_result(load_links(visuals, default, keep, self._cancel))
        except BaseException as error:  # delivered to render(), which reports it once
            self._loading.set_exception(error)

    @property
    def loaded(self) -> bool:
        """Whether the meshes are read (they are uploaded at the next render)."""
        return self._loading.done()

    def wait_loaded(self, timeout: float | None = None) -> None:
        """Block until the loader is done (tools and tests; render never waits); raises its error."""
        self._loading.exception(timeout)

    def render(self, ctx: moderngl.Context, view: RenderView) -> None:
        if self._links is None:
            if not self._loading.done():
                return
            self._links = []  # a loading error is raised once, then nothing is drawn
            self._links = [_Link(self.prefix + link, [GpuMesh(ctx, self.program, part) for part in parts],
                                 self._overrides.get(link))
                           for link, parts in self._loading.result().items()]
        self.begin(ctx, view)
        graph, world, view_matrix = self.transform_graph, view.frame, view.view
        missing: list[str] = []
        first_error = ""
        for link in self._links:
            try:
                pose = graph.lookup(world, link.frame)
            except LookupError as error:
                if link.frame not in self._missing:
                    missing.append(link.frame)
                    self._missing.add(link.frame)
                    first_error = first_error or str(error)
                continue
            dependencies = graph.query(world, link.frame).dependencies
            if self.wait_for_joints and any(isinstance(dependency, KinematicModel) and dependency.version == 0
                                            for dependency in dependencies):
                continue
            self.shown.add_graph(dependencies)
            model_view = view_matrix @ pose
            for mesh in link.meshes:
                self.draw(mesh, model_view, link.color or (1.0, 1.0, 1.0, 1.0), link.color is not None)
        if missing:  # once per link: the graph may get the robot later (its TransformationInterface)
            log.warning("%s: links not drawn until the transformation graph can place them in %s (load the "
                        "URDF with a TransformationInterface, prefix %r): %s (first error: %.300s)", self.name,
                        world, self.prefix, ", ".join(missing), first_error)

    def on_stop(self) -> None:
        self._cancel.set()

    def gl_release(self) -> None:
        for link in self._links or ():
            for mesh in link.meshes:
                mesh.release()
        self._links = None
        super().gl_release()

    @property
    def triangles(self) -> int:
        """Triangles drawn per view once loaded (0 before)."""
        return sum(mesh.part.triangles for link in self._links or () for mesh in link.meshes)
