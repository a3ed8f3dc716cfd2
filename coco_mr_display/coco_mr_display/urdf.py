"""GLUrdf: a robot drawn from its URDF's visual meshes, every link posed from the transformation graph.

The kinematics are not computed here, nor is the URDF read again: a TransformationInterface of the
same process loads the robot into the application's graph (Pinocchio for the kinematics, the visuals
from the same parse: :class:`~coco_core.transforms.urdf.UrdfModel`) and writes the joint values;
GLUrdf draws that model's visuals and looks up ``T_world_link`` of each link once per view (the graph
caches paths and values, and Pinocchio computes all placements in one pass per joint update). The
application names the robot's file once, and what is drawn cannot disagree with what is computed.

Loading is split so that errors are immediate and the render loop never waits:

- ``on_config`` (fast, synchronous; ``init`` with ``preload``): find the model in the graph (an
  unknown name lists the ones there are), resolve every mesh file (a missing one fails here, named),
  check the ``colors`` link names against the model's links;
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

import logging
import threading
from collections import OrderedDict
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from coco_core.attributes import Attribute
from coco_core.component import UnknownNameError
from coco_core.errors import AttributeValueError, did_you_mean
from coco_core.transforms.graph import KinematicModel, TransformGraph
from coco_core.transforms.resources import resolve
from coco_core.transforms.urdf import UrdfModel, UrdfVisual

from . import mesh_cache
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


def robot_model(graph: TransformGraph, name: str, component: str) -> UrdfModel:
    """The URDF model ``name`` of ``graph`` (any name: the only one); an error lists the ones there are."""
    models = {key: model for key, model in graph.models.items() if isinstance(model, UrdfModel)}
    if name in models:
        return models[name]
    if not name and len(models) == 1:
        return next(iter(models.values()))
    hint = ("load it with a TransformationInterface (its urdf attribute) in this process, declared before "
            "the display" if not models
            else f"name one with the robot attribute; {did_you_mean(name, models)}")
    raise UnknownNameError(f"{component}: the transformation graph has "
                           f"{'no URDF model ' + repr(name) if name else str(len(models)) + ' URDF models'}: {hint}")


def mesh_paths(model: UrdfModel) -> dict[str, Path]:
    """Each mesh file name of the model's visuals -> the file (relative names from the URDF's folder);
    a missing file fails here, named."""
    folder = model.source.parent if model.source is not None else None
    return {visual.filename: resolve(visual.filename, folder) for visual in model.visuals if visual.shape == "mesh"}


_VisualKey = tuple[Path, int, int, bytes, tuple[float, ...] | None, tuple[float, ...], float]

LOADED_BYTES = 256 * 2**20
"""The most memory :data:`_LOADED` holds (Baxter's parts: ~5 MB unsimplified); beyond it, the parts
used least recently are let go (a mesh file changed since, a robot no longer shown)."""


class LoadedParts:
    """The parts of the mesh visuals this process loaded, by file (path, size, modification time) and
    by what is baked into them (origin, scale, colour, fraction kept), read-only: a robot shown by
    several GLUrdf peers of one process (two views, a display rebuilt by a reconfiguration, ``--check``
    building every process's part in the launcher) reads and simplifies its meshes once (Baxter's:
    ~2.5 s of CPU). At most ``limit`` bytes, the least recently used let go first, so that a long run
    that loads many models (or one whose files change) does not grow without end. Between
    processes, with ``COCO_MESH_CACHE`` set: :mod:`.mesh_cache`."""

    def __init__(self, limit: int = LOADED_BYTES) -> None:
        self.limit = limit
        self._parts: OrderedDict[_VisualKey, list[MeshPart]] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()

    def get(self, key: _VisualKey) -> list[MeshPart] | None:
        with self._lock:
            parts = self._parts.get(key)
            if parts is not None:
                self._parts.move_to_end(key)
            return parts

    def put(self, key: _VisualKey, parts: list[MeshPart]) -> None:
        with self._lock:
            if key in self._parts:
                return
            self._parts[key] = parts
            self._bytes += sum(part.nbytes for part in parts)
            while self._bytes > self.limit and len(self._parts) > 1:
                _, old = self._parts.popitem(last=False)
                self._bytes -= sum(part.nbytes for part in old)

    def __len__(self) -> int:
        return len(self._parts)


_LOADED = LoadedParts()


def _mesh_visual_parts(path: Path, visual: UrdfVisual, color: tuple[float, ...], keep: float,
                       files: dict[Path, Any]) -> list[MeshPart]:
    """The parts of one mesh visual, from :data:`_LOADED` when this process made them already from the
    same file as it is now; ``files`` the geometries this load has read (each file read once)."""
    try:
        stat = path.stat()
    except OSError:  # gone since it was resolved: load_geometry names it
        stat = None
    scale = None if visual.scale is None else tuple(float(value) for value in visual.scale)
    key = (path, stat.st_size if stat else -1, stat.st_mtime_ns if stat else -1,
           np.asarray(visual.origin, dtype=float).tobytes(), scale, tuple(float(value) for value in color), float(keep))
    cached = _LOADED.get(key)
    if cached is not None:
        return cached
    kept = mesh_cache.entry(key) if stat is not None else None  # COCO_MESH_CACHE: another process's
    new = mesh_cache.read(kept) if kept is not None and kept.exists() else None
    if new is None:
        if path not in files:
            files[path] = load_geometry(path)
        new = parts_of(files[path], visual.origin, visual.scale, color, keep=keep, label=str(path))
        if kept is not None:
            mesh_cache.write(kept, new)
    for part in new:
        for array in part.arrays().values():
            array.setflags(write=False)  # shared by every peer that draws this file
    _LOADED.put(key, new)
    return new


def load_links(visuals: list[UrdfVisual], paths: dict[str, Path], default_color: tuple[float, ...], keep: float,
               cancelled: threading.Event) -> dict[str, list[MeshPart]]:
    """The merged parts of every link with visuals (the loader thread's work); ``paths`` from
    :func:`mesh_paths`."""
    files: dict[Path, Any] = {}
    parts: dict[str, list[MeshPart]] = {}
    for visual in visuals:
        if cancelled.is_set():
            break
        color = visual.color or default_color
        if visual.shape == "mesh":
            new = _mesh_visual_parts(paths[visual.filename], visual, color, keep, files)
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
    """A URDF robot's visual meshes, each link at its transformation-graph pose: the robot model that a
    TransformationInterface of this process loaded into the graph, so the file is named and parsed once."""

    robot = Attribute(str, "", "name of the URDF model in the transformation graph (a TransformationInterface's: "
                      "the robot's name, after its prefix); empty: the graph's only one")
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
        self._prefix = ""
        self._overrides: dict[str, tuple[float, float, float, float]] = {}
        self._missing: set[str] = set()
        self._cancel = threading.Event()
        self._loading: Future = Future()
        if self.preload:  # while the application is built: its start (and the other processes') waits
            self._load(*self._work())
            self._loading.result()  # a bad mesh fails the application's construction, with its message

    def on_config(self) -> None:
        if not self.preload:
            threading.Thread(target=self._load, args=self._work(), name=f"{self.name}-loader", daemon=True).start()

    def _work(self) -> tuple[list[UrdfVisual], dict[str, Path], tuple[float, ...], float]:
        """What the loader needs, checked: the model's visuals and mesh files, the default colour and
        the fraction of triangles kept."""
        model = robot_model(self.transform_graph, self.robot, self.name)
        overrides = parse_link_colors(self.colors)
        for link in overrides:
            if link not in model.link_names:
                raise UnknownNameError(f"{self.name}: colors names link {link!r}, which robot {model.name} does not "
                                       f"have; {did_you_mean(link, model.link_names)}")
        self._prefix, self._overrides = model.prefix, overrides
        default = tuple(self.color) + ((1.0,) if len(self.color) == 3 else ())
        return model.visuals, mesh_paths(model), default, self.simplify

    def _load(self, visuals: list[UrdfVisual], paths: dict[str, Path], default: tuple[float, ...],
              keep: float) -> None:
        try:
            self._loading.set_result(load_links(visuals, paths, default, keep, self._cancel))
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
            self._links = [_Link(self._prefix + link, [GpuMesh(ctx, self.program, part) for part in parts],
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
            log.warning("%s: links not drawn until the transformation graph can place them in %s: %s "
                        "(first error: %.300s)", self.name, world, ", ".join(missing), first_error)

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
