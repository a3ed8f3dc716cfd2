"""Display: frames per second at 640x480 headless (EGL), Baxter and Baxter + a live RGB-D mesh, vs pyrender.

A *frame* is what a display application does each period: the Baxter joints move (the next row of a
real recording, ``shared/data/baxter/shake_hand.dat``, set on the transformation graph), a new RGB-D
frame arrives (the two Redwood frames in turn, 640x480, 307k vertices, 612k grid triangles), the scene
is drawn and the colour image is read back (the render-to-texture output; it also waits for the GPU).

- CoCo: one ``GLManager.step()`` (headless EGL context, mono) with a GLCameraManager, GLUrdf (Baxter's
  visual meshes from example-robot-data) and, in the RGB-D rows, GLRGBDImage (``max_edge`` 5 cm; the
  depth is unprojected on the GPU, a new frame is two texture writes). Rows: full detail (every depth
  pixel a vertex, every Baxter triangle), GLRGBDImage's default automatic stride (level of detail from
  the surface's size on screen, ``vertex_spacing`` 1 px), and the goal configurations: Baxter
  ``simplify`` 0.25 and ``vertex_spacing`` 1.5 or 2 px, the two quality knobs a user sets.
- Quality: each CoCo row's first frame is compared with the full-detail render of the same frame:
  IoU of the pixels covered, and the share of covered pixels whose colour differs by more than 16/255.
- Anchor: pyrender's OffscreenRenderer (EGL) on the same meshes, poses, camera and RGB-D data: each
  link node gets its pose from the same graph, the RGB-D frame becomes a new mesh each frame (numpy
  unprojection, triangles filtered by the same rules, per-vertex colours; pyrender uploads it when it
  renders). pyrender always reads back colour and depth; CoCo reads back colour.

Goal: Baxter + 640x480 RGB-D mesh at >= 30 fps. A second table gives the cost of taking in a new RGB-D
frame, a third where the time of a CoCo frame goes (cProfile: draw calls, read-back, texture writes,
Python). A fourth is the palpation app's view (config/palpation_replay.xml: the RGB-D surface seen
from its display camera, the hand, the proxy, the force arrow): a frame for a new camera frame (the
surface drawn) against a frame for a new pose only (the surface's kept drawing put back), measured
side by side; the issue-34 goal is >= 30 fps for the view. The tables name the renderer the GL context reports (``GL_RENDERER``): Mesa's llvmpipe on a
machine without a GPU (everything on the CPU), a GPU's driver elsewhere.

    .venv/bin/python bench/bench_display.py [--json PATH] [--no-plot]
"""

from __future__ import annotations

import cProfile
import logging
import os
import pstats
import sys
import threading
from itertools import cycle, repeat
from typing import Any, Callable

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")  # pyrender's context: EGL, no display

import _report
from _table import Table, fmt_ratio, fmt_time_ns, verdict
from _timing import Loop, Samples, measure

for _package in ("coco_mr_vision", "coco_mr_display"):
    if str(_report.REPO / _package) not in sys.path:
        sys.path.insert(0, str(_report.REPO / _package))

import numpy as np

from coco_core.application import Application
from coco_core.component import Component
from coco_core.ports import InputPort, OutputPort
from coco_core.transforms import se3
from coco_core.transforms.urdf import load_urdf
from coco_mr_display.camera import GLCameraManager
from coco_mr_display.entity import GLEntity
from coco_mr_display.manager import GLManager
from coco_mr_display.rgbd import GLRGBDImage
from coco_mr_display.surface_triangles import grid_indices
from coco_mr_display.urdf import GLUrdf, load_links, mesh_paths, robot_model
from coco_mr_vision.image import CameraIntrinsics, Image
from coco_mr_vision.rgbd import RGBDFrame

BAXTER_URDF = "package://example-robot-data/robots/baxter_description/urdf/baxter.urdf"
DATA = _report.REPO.parent / "shared" / "data"
SHAKE_HAND = DATA / "baxter" / "shake_hand.dat"
REDWOOD = DATA / "rgbd" / "redwood"
SIZE = (640, 480)
GOAL_FPS = 30.0
MAX_EDGE = 0.05
REPEATS, TARGET_S = 5, 0.6
MIN_OVERLAP = 0.9
"""Least intersection over union of the pixels CoCo and pyrender cover, checked before timing (CoCo's
from its colour read-back: pure black pixels, such as Baxter's head screen, count as empty)."""
LIGHT = 0.25
"""GLUrdf ``simplify`` of the light scene: the fraction of Baxter's triangles kept (quadric decimation)."""

VIEWER = {"position": [3.6, 2.0, 1.7], "look_at": [0.6, 0.0, 0.5], "fov_y": 50.0}
"""Where the display's camera is: Baxter on the left, the RGB-D surface on the right of the view."""
PALPATION_CAMERA = se3.make(se3.rpy_to_matrix(-0.17, 0.0, 0.0), (0.0, -0.12, -0.15))
"""The palpation app's view (config/palpation_replay.xml): its display_camera in the RGB-D camera's frame."""
HAND_MESH = _report.REPO / "config" / "meshes" / "hand.obj"
RGBD_CAMERA = se3.make(np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]), (2.6, -1.2, 1.1))
"""Pose of the RGB-D camera's optical frame in the world: 1.2 m to Baxter's right, looking along -x."""

SPACINGS = (1.5, 2.0)
"""GLRGBDImage ``vertex_spacing`` of the goal configurations (pixels between neighbouring vertices)."""
COLOUR_TOLERANCE = 16
"""A pixel's colour 'differs' from the full-detail render when a channel is off by more than this."""

COCO_BAXTER, COCO_RGBD, COCO_AUTO, COCO_LIGHT, COCO_RGBD_ONLY = (
    "CoCo Baxter", "CoCo Baxter + RGB-D, full detail (stride 1)", "CoCo Baxter + RGB-D, automatic stride",
    f"CoCo Baxter simplify {LIGHT} + RGB-D, automatic stride", "CoCo RGB-D alone, stride 1")
COCO_GOALS = [f"CoCo Baxter simplify {LIGHT} + RGB-D, automatic stride, spacing {spacing:g} px" for spacing in SPACINGS]
GOAL_ROWS = (COCO_RGBD, COCO_AUTO, COCO_LIGHT, *COCO_GOALS)
PYR_BAXTER, PYR_RGBD = "pyrender Baxter", "pyrender Baxter + RGB-D"


# --- shared inputs ------------------------------------------------------------------------------------

def motion() -> list[dict[str, float]]:
    """Joint values of each row of the recording (the neutral pose when the data is absent)."""
    if not SHAKE_HAND.exists():
        print(f"{SHAKE_HAND} is absent: Baxter stays in its neutral pose")
        return [{}]
    header = SHAKE_HAND.read_text().splitlines()[0].split(",")
    rows = np.loadtxt(SHAKE_HAND, delimiter=",", skiprows=1)
    joints = [(i, name) for i, name in enumerate(header) if name != "time" and not name.endswith("gripper")]
    return [{name: float(row[i]) for i, name in joints} for row in rows]


def rgbd_frames() -> list[RGBDFrame]:
    if not REDWOOD.exists():
        raise SystemExit(f"{REDWOOD} is absent: the RGB-D rows need the shared Redwood frames")
    intrinsics = CameraIntrinsics.from_json(REDWOOD / "camera_primesense.json")
    return [RGBDFrame.load(REDWOOD / "color" / f"{i:05d}.jpg", REDWOOD / "depth" / f"{i:05d}.png", intrinsics)
            for i in (0, 1)]


def scene_graph(app: Application) -> None:
    """Baxter's URDF on the graph, standing at the world origin, and the RGB-D camera's frame."""
    load_urdf(app.transforms, BAXTER_URDF)
    app.transforms.add_static("world", "base")
    app.transforms.add_static("world", "rgbd_camera", RGBD_CAMERA)


# --- CoCo ---------------------------------------------------------------------------------------------

class Sensor(Component):
    rgbd = OutputPort(RGBDFrame)


class Screen(Component):
    frames = InputPort(Image)


class CocoScene:
    """A configured GLManager with its peers, stepped by hand (the activity's job) one frame at a time."""

    def __init__(self, name: str, baxter: bool, rgbd: bool, stride: int = 1, simplify: float = 1.0,
                 spacing: float = 1.0) -> None:
        self.app = Application(name)
        scene_graph(self.app)
        self.manager = GLManager("display", width=SIZE[0], height=SIZE[1], visualization="mono")
        self.manager.add_peer(GLCameraManager("camera", **VIEWER))
        self.urdf = self.manager.add_peer(GLUrdf("baxter", simplify=simplify)) if baxter else None
        self.surface = self.manager.add_peer(GLRGBDImage("surface", frame="rgbd_camera", max_edge=MAX_EDGE,
                                                         stride=stride, vertex_spacing=spacing)) if rgbd else None
        self.sensor, self.screen = Sensor("sensor"), Screen("screen")
        for component in (self.manager, self.sensor, self.screen):
            self.app.add(component)
        if rgbd:
            self.app.connect(self.sensor.rgbd, "surface.rgbd")
        self.app.connect(self.manager.color, self.screen.frames)
        if not self.manager.configure():
            raise SystemExit(f"{name}: GLManager could not start (see the log above)")
        assert self.manager.surface is not None
        self.ctx = self.manager.surface.ctx
        if self.urdf is not None:
            self.urdf.wait_loaded()

    def frame(self, pose: dict[str, float], rgbd: RGBDFrame) -> np.ndarray:
        """One frame (with this scene's context current): move, send, draw; the image read back."""
        if self.urdf is not None:
            self.app.transforms.set_joints(pose)
        if self.surface is not None:
            self.sensor.rgbd.write(rgbd)
        self.manager.step()
        return self.screen.frames.read()[1].data

    def loop(self, poses: list[dict[str, float]], frames: list[RGBDFrame]) -> Loop:
        frame, pose_cycle, frame_cycle = self.frame, cycle(poses), cycle(frames)

        def run(n: int) -> None:
            with self.ctx:  # several contexts live in this process: make this one current
                for _ in repeat(None, n):
                    frame(next(pose_cycle), next(frame_cycle))

        return run

    @property
    def triangles(self) -> int:
        """Triangles of the scene per frame (the RGB-D grid at the stride of the last frame, before the
        rubber sheets and holes are left out)."""
        grid = 0
        if self.surface is not None:
            columns, rows = (-(-extent // self.surface.last_stride) for extent in SIZE)
            grid = 2 * (columns - 1) * (rows - 1)
        return grid + (self.urdf.triangles if self.urdf is not None else 0)

    @property
    def stride(self) -> str:
        return str(self.surface.last_stride) if self.surface is not None else "-"

    def close(self) -> None:
        self.ctx.__enter__()  # current for the release; the context is gone afterwards, nothing to restore
        self.manager.stop()


def upload_loop(scene: CocoScene, frames: list[RGBDFrame]) -> Loop:
    """A new RGB-D frame into GLRGBDImage: port read, two texture writes, until the GPU has them."""
    peer, write, frame_cycle = scene.surface, scene.sensor.rgbd.write, cycle(frames)
    assert peer is not None

    def run(n: int) -> None:
        with scene.ctx:
            for _ in repeat(None, n):
                write(next(frame_cycle))
                peer.step()
                peer.upload(scene.ctx)
                scene.ctx.finish()

    return run


class PalpationView:
    """The palpation app's view as config/palpation_replay.xml sets it: the RGB-D frame seen from the
    display camera (``vertex_spacing`` 3, ``max_edge`` 5 cm), the hand mesh, the proxy sphere and the
    force arrow, the colour read back. Each frame moves the hand, the proxy and the arrow (a pose
    arrived); with ``camera`` it also sends a new RGB-D frame (a camera frame arrived)."""

    def __init__(self, camera: bool) -> None:
        self.app = Application("palpation_view")
        self.manager = GLManager("display", width=SIZE[0], height=SIZE[1], world="camera",
                                 background=[0.16, 0.17, 0.20])
        rotation, eye = PALPATION_CAMERA[:3, :3], PALPATION_CAMERA[:3, 3]
        self.manager.add_peer(GLCameraManager("view_camera", position=list(eye), look_at=list(eye + rotation[:, 2]),
                                              up=list(-rotation[:, 1]), fov_y=45.0))
        self.surface = self.manager.add_peer(GLRGBDImage("scene", max_edge=MAX_EDGE, vertex_spacing=3.0))
        self.hand = self.manager.add_peer(GLEntity("hand", mesh=str(HAND_MESH), color=[0.2, 0.8, 0.2]))
        self.proxy = self.manager.add_peer(GLEntity("proxy", mesh="sphere", size=[0.008], color=[1.0, 1.0, 1.0]))
        self.arrow = self.manager.add_peer(GLEntity("force_arrow", mesh="arrow", size=[0.004, 0.05],
                                                    color=[0.2, 0.6, 1.0]))
        self.sensor, self.screen = Sensor("sensor"), Screen("screen")
        for component in (self.manager, self.sensor, self.screen):
            self.app.add(component)
        self.app.connect(self.sensor.rgbd, "scene.rgbd")
        self.app.connect(self.manager.color, self.screen.frames)
        if not self.manager.configure():
            raise SystemExit("palpation view: GLManager could not start (see the log above)")
        assert self.manager.surface is not None
        self.ctx = self.manager.surface.ctx
        self.camera = camera
        with self.ctx:  # the surface's first frame (a view without one draws no surface)
            self.sensor.rgbd.write(rgbd_frames()[0])
            self.manager.step()

    def loop(self, frames: list[RGBDFrame]) -> Loop:
        frame_cycle, send, step, read = cycle(frames), self.sensor.rgbd.write, self.manager.step, self.screen.frames.read
        moving = (self.hand, self.proxy, self.arrow)
        counter = iter(range(1 << 62))

        def run(n: int) -> None:
            with self.ctx:
                for _ in repeat(None, n):
                    x = 0.05 * np.sin(next(counter) * 0.1)
                    for entity in moving:
                        entity.position = [x, 0.05, 0.9]
                    if self.camera:
                        send(next(frame_cycle))
                    step()
                    read()

        return run

    def close(self) -> None:
        self.ctx.__enter__()
        self.manager.stop()


PALPATION_ROWS = ("a camera frame arrived (the surface drawn)", "a pose arrived (the surface put back)")


def palpation_table(samples: dict[str, Samples], repaints: dict[str, int], others: str) -> tuple[Table, dict[str, Any]]:
    drawn = samples[PALPATION_ROWS[0]]
    t = Table("Display - the palpation app's view, 640x480 headless (median of repeats)",
              ["frame", "ms/frame", "fps", "vs surface drawn (x faster)", f"goal >= {GOAL_FPS:g} fps"])
    results: dict[str, Any] = {}
    for name, s in samples.items():
        t.add(name, f"{s.median / 1e6:.1f}", f"{fps(s):.1f}", fmt_ratio(s.ratio_to(drawn)),
              verdict(fps(s) >= GOAL_FPS))
        results[name] = {**s.to_json(), "surface_repaints": repaints[name]}
    t.notes += [
        "The view of config/palpation_replay.xml: the Redwood frame seen from the app's display camera (GLRGBDImage "
        "vertex_spacing 3, max_edge 5 cm: stride 2-3 here), the hand mesh, the proxy sphere and the force arrow; "
        "every frame moves the hand, the proxy and the arrow and reads the colour back. A camera frame: a new "
        "RGB-D frame too, so the surface is drawn (into its cache, then copied into the frame); a pose only: the "
        "surface's kept drawing is copied in (a blit of colour and depth) and only the small meshes are drawn.",
        f"Other processes used {others} of the {os.cpu_count()} cores meanwhile.",
    ]
    return t, results


# --- pyrender (anchor) --------------------------------------------------------------------------------

class CpuSurface:
    """The RGB-D frame as a mesh built on the CPU, as a renderer without GPU unprojection needs it."""

    def __init__(self, width: int, height: int) -> None:
        self.triangles = grid_indices(width, height).reshape(-1, 3)

    def build(self, frame: RGBDFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(positions in the optical frame, colours RGB 0..1, kept triangles): same rules as GLRGBDImage."""
        k = frame.intrinsics
        assert k is not None
        z = frame.depth_metres()
        height, width = z.shape
        u = np.arange(width, dtype=np.float32)[None, :]
        v = np.arange(height, dtype=np.float32)[:, None]
        points = np.stack([(u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z], axis=-1).reshape(-1, 3)
        valid = np.isfinite(points[:, 2])
        triangles = self.triangles[valid[self.triangles].all(axis=1)]
        a, b, c = (points[triangles[:, k]] for k in range(3))
        longest = np.max([np.einsum("ij,ij->i", d, d) for d in (b - a, c - b, a - c)], axis=0)
        triangles = triangles[longest <= MAX_EDGE ** 2]
        colors = frame.color.to_rgb().reshape(-1, 3).astype(np.float32) / 255.0
        return np.nan_to_num(points), colors, triangles


class PyrenderScene:
    """The same scene in pyrender: Baxter's links as nodes posed from the graph, the RGB-D mesh rebuilt
    for each frame."""

    def __init__(self, baxter: bool, rgbd: bool, view_matrix: np.ndarray, simplify: float) -> None:
        import pyrender
        import trimesh

        self.pyrender = pyrender
        self.app = Application("pyrender")
        scene_graph(self.app)
        self.scene = pyrender.Scene(bg_color=[0.0, 0.0, 0.0, 1.0], ambient_light=[0.3, 0.3, 0.3])
        camera = pyrender.PerspectiveCamera(yfov=np.radians(VIEWER["fov_y"]), aspectRatio=SIZE[0] / SIZE[1],
                                            znear=0.05, zfar=100.0)
        camera_pose = se3.inverse(view_matrix)
        self.scene.add(camera, pose=camera_pose)
        self.scene.add(pyrender.DirectionalLight(intensity=3.0), pose=camera_pose)
        self.links: list[tuple[str, Any]] = []
        self.triangles = 0
        if baxter:
            model = robot_model(self.app.transforms, "baxter", "pyrender")
            links = load_links(model.visuals, mesh_paths(model), (0.6, 0.6, 0.6, 1.0), keep=simplify,
                               cancelled=threading.Event())
            for link, parts in links.items():
                meshes = [trimesh.Trimesh(part.positions, part.indices, process=False,
                                          vertex_colors=part.colors if part.colors is not None else None)
                          for part in parts]
                self.triangles += sum(part.triangles for part in parts)
                node = self.scene.add(pyrender.Mesh([pyrender.Mesh.from_trimesh(m).primitives[0] for m in meshes]))
                self.links.append((link, node))
        self.cpu = CpuSurface(*SIZE) if rgbd else None
        self.surface_node: Any = None
        self.renderer = pyrender.OffscreenRenderer(*SIZE)

    def new_surface(self, frame: RGBDFrame) -> None:
        assert self.cpu is not None
        positions, colors, triangles = self.cpu.build(frame)
        material = self.pyrender.MetallicRoughnessMaterial(baseColorFactor=[1.0, 1.0, 1.0, 1.0])
        primitive = self.pyrender.Primitive(positions=positions, indices=triangles, color_0=colors, material=material)
        if self.surface_node is not None:
            self.scene.remove_node(self.surface_node)
        self.surface_node = self.scene.add(self.pyrender.Mesh([primitive]), pose=RGBD_CAMERA)

    def frame(self, pose: dict[str, float], rgbd: RGBDFrame) -> np.ndarray:
        """One frame: move (link poses from the graph), new surface, render; the depth read back."""
        if self.links:
            self.app.transforms.set_joints(pose)
            for link, node in self.links:
                self.scene.set_pose(node, self.app.transforms.lookup("world", link))
        if self.cpu is not None:
            self.new_surface(rgbd)
        return self.renderer.render(self.scene)[1]

    def loop(self, poses: list[dict[str, float]], frames: list[RGBDFrame]) -> Loop:
        frame, pose_cycle, frame_cycle = self.frame, cycle(poses), cycle(frames)

        def run(n: int) -> None:
            for _ in repeat(None, n):
                frame(next(pose_cycle), next(frame_cycle))

        return run


def compare(image: np.ndarray, reference: np.ndarray) -> dict[str, float]:
    """What a cheaper configuration costs in pixels: IoU of the covered pixels (pure black counts as
    empty), and the share of pixels covered in both whose colour differs by more than COLOUR_TOLERANCE."""
    drawn, expected = image.any(axis=2), reference.any(axis=2)
    both = drawn & expected
    differs = np.abs(image.astype(int) - reference).max(axis=2) > COLOUR_TOLERANCE
    return {"iou": float(both.sum() / max(1, (drawn | expected).sum())),
            "colour_differs": float(differs[both].mean()) if both.any() else 0.0}


def same_scene(coco: CocoScene, anchor: PyrenderScene, pose: dict[str, float], rgbd: RGBDFrame) -> float:
    """Intersection over union of what each renderer covers in the same frame: checks, before timing,
    that both draw the same scene from the same camera."""
    with coco.ctx:
        drawn = coco.frame(pose, rgbd).any(axis=2)
    covered = anchor.frame(pose, rgbd) > 0
    return float((drawn & covered).sum() / max(1, (drawn | covered).sum()))


# --- profile --------------------------------------------------------------------------------------------

CATEGORIES: list[tuple[str, Callable[[str], bool]]] = [
    ("GL draw calls", lambda f: "'render' of 'mgl.VertexArray'" in f),
    ("colour read-back (waits for rasterisation)", lambda f: "'read_into' of 'mgl.Framebuffer'" in f),
    ("texture writes (new RGB-D frame)", lambda f: "'write' of 'mgl.Texture" in f),
]


def profile(run: Loop, frames: int) -> dict[str, float]:
    """Seconds per frame by category, from cProfile's own time of the moderngl calls; the rest is Python
    (CoCo's components, the graph, uniforms, numpy) plus profiling overhead."""
    profiler = cProfile.Profile()
    profiler.enable()
    run(frames)
    profiler.disable()
    stats = pstats.Stats(profiler).stats  # type: ignore[attr-defined]
    total = sum(entry[2] for entry in stats.values())
    shares = {name: 0.0 for name, _ in CATEGORIES}
    for (_, _, function), entry in stats.items():
        for name, matches in CATEGORIES:
            if matches(function):
                shares[name] += entry[2]
    shares["Python (components, graph, uniforms) + profiler"] = total - sum(shares.values())
    return {name: seconds / frames for name, seconds in shares.items()}


# --- tables and plot --------------------------------------------------------------------------------

def fps(samples: Samples) -> float:
    return 1e9 / samples.median


def on_llvmpipe(renderer: str) -> bool:
    """Whether the context renders with Mesa's llvmpipe (on the CPU), whose threads the notes explain."""
    return "llvmpipe" in renderer.lower()


def renderer_note(renderer: str) -> str:
    """What the renderer does on the calling thread and where rasterisation runs, for the renderer at hand."""
    if on_llvmpipe(renderer):
        return ("llvmpipe runs vertex processing on the calling thread and rasterises on LP_NUM_THREADS threads "
                f"({os.environ.get('LP_NUM_THREADS', 'default: one per core')}).")
    return (f"{renderer} renders on its own hardware: a draw call queues the work and returns, the colour "
            "read-back waits for the GPU to finish the frame.")


def frame_table(samples: dict[str, Samples], triangles: dict[str, int], strides: dict[str, str],
                quality: dict[str, dict[str, float]], overlap: dict[str, float],
                others: str, renderer: str) -> tuple[Table, dict[str, Any]]:
    t = Table(f"Display - frames per second, {SIZE[0]}x{SIZE[1]} headless, {renderer} (median of repeats)",
              ["scene", "triangles", "RGB-D stride", "ms/frame", "fps", "vs pyrender (x faster)",
               "vs full detail: IoU", f"colour differs", f"goal >= {GOAL_FPS:g} fps"])
    results: dict[str, Any] = {}
    for name, s in samples.items():
        anchor = samples.get(PYR_BAXTER if name == COCO_BAXTER else PYR_RGBD) if name.startswith("CoCo") else None
        ratio = s.ratio_to(anchor) if anchor is not None else float("nan")
        goal = fps(s) >= GOAL_FPS if name in GOAL_ROWS else None
        q = quality.get(name)
        t.add(name, f"{triangles[name] / 1e3:.0f}k", strides.get(name, "-"), f"{s.median / 1e6:.1f}",
              f"{fps(s):.1f}", fmt_ratio(ratio) if anchor is not None else "-",
              f"{q['iou']:.3f}" if q else "-", f"{q['colour_differs']:.1%}" if q else "-", verdict(goal))
        results[name] = {**s.to_json(), "fps": fps(s), "triangles": triangles[name], "stride": strides.get(name),
                         "vs_full_detail": q, "x_faster_than_pyrender": ratio if anchor is not None else None,
                         "goal_met": goal}
    t.notes += [
        "A frame: Baxter joints from the next row of shake_hand.dat, a new RGB-D frame (Redwood 0 and 1 in "
        "turn), draw, colour read-back. Triangles: Baxter's (culled back faces included) + the RGB-D grid at "
        "the row's stride (612k at stride 1, 153k at 2, 68k at 3) before those with "
        f"an unknown vertex or an edge > {MAX_EDGE * 100:g} cm are left out. The automatic stride is chosen per "
        "frame from the surface's size on screen; the column shows the one of the last frame.",
        f"simplify {LIGHT}: GLUrdf keeps about {LIGHT:.0%} of Baxter's triangles (quadric decimation at load). "
        "spacing: GLRGBDImage's vertex_spacing, the most screen pixels between neighbouring vertices that the "
        "automatic stride allows (default 1).",
        f"vs full detail: the first frame compared with '{COCO_RGBD}' (Baxter alone with itself): IoU of the "
        f"covered pixels, share of pixels covered in both whose colour differs by > {COLOUR_TOLERANCE}/255.",
        "Same scene: the pixels covered by CoCo and pyrender in the first frame overlap with IoU "
        + ", ".join(f"{iou:.3f} ({name})" for name, iou in overlap.items()) + " (checked before timing).",
        "pyrender rebuilds the full-resolution RGB-D mesh on the CPU each frame (numpy, same triangle rules) and "
        "reads back colour and depth; it lights the normal-less RGB-D mesh (darker), CoCo shows it unlit. "
        f"Ratios are medians of per-round ratios ({REPEATS} interleaved rounds); every RGB-D row is compared "
        "with pyrender's full-detail scene.",
        f"Other processes used {others} of the {os.cpu_count()} cores meanwhile; {renderer_note(renderer)}",
    ]
    return t, results


def upload_table(samples: dict[str, Samples]) -> tuple[Table, dict[str, Any]]:
    coco, anchor, floor = (samples[name] for name in UPLOADS)
    t = Table("Display - taking in a new 640x480 RGB-D frame (per frame, median of repeats)",
              ["variant", "time", "vs CPU mesh (x cheaper)", "vs memcpy (x dearer)"])
    results: dict[str, Any] = {}
    for name, s in samples.items():
        t.add(name, fmt_time_ns(s.median), fmt_ratio(s.ratio_to(anchor)), fmt_ratio(floor.ratio_to(s)))
        results[name] = s.to_json()
    t.notes += ["CoCo: port read + two texture writes (colour RGB8/BGR8 as is, depth 16 bit), then glFinish. "
                "CPU mesh: what the anchor does before pyrender uploads (unprojection, triangle filter, "
                "colours), GPU upload not included. Floor: copying the frame's 1.5 MB in numpy."]
    return t, results


def profile_table(breakdown: dict[str, dict[str, float]], renderer: str) -> tuple[Table, dict[str, Any]]:
    names = list(breakdown)
    t = Table(f"Display - where a CoCo frame's time goes on {renderer} (cProfile, ms per frame)", ["part", *names])
    for part in next(iter(breakdown.values())):
        t.add(part, *(f"{breakdown[name][part] * 1e3:.1f}" for name in names))
    if on_llvmpipe(renderer):
        t.notes.append("Own time of the moderngl calls: a draw call returns once llvmpipe has run the vertex "
                       "shaders and binned the triangles on the calling thread; the read-back waits for "
                       "the rasteriser threads. The Python row is everything else in the frame.")
    else:
        t.notes.append(f"Own time of the moderngl calls: a draw call returns once {renderer}'s driver has queued "
                       "it; the read-back waits for the GPU to finish the frame. The Python row is everything "
                       "else in the frame.")
    return t, breakdown


UPLOADS = ("CoCo GLRGBDImage upload", "CPU mesh (numpy)", "memcpy of the frame (floor)")


def draw(frames: dict[str, Samples], triangles: dict[str, int],
         quality: dict[str, dict[str, float]], renderer: str, palpation: dict[str, Samples]) -> Callable[[Any], Any]:
    def figure(plt: Any) -> Any:
        names = list(frames) + [f"palpation view: {name}" for name in palpation]
        values = [fps(frames[name]) for name in frames] + [fps(s) for s in palpation.values()]
        colors = ["tab:red" if name.startswith("pyrender") else "tab:orange" if name.startswith("palpation")
                  else "tab:blue" for name in names]
        fig, ax = plt.subplots(figsize=(10, 4.4))
        ax.barh(names, values, color=colors)
        ax.invert_yaxis()
        ax.tick_params(axis="y", labelsize=8)
        ax.axvline(GOAL_FPS, color="tab:green", linestyle="--", label=f"goal: {GOAL_FPS:g} fps (Baxter + RGB-D)")
        for y, (name, value) in enumerate(zip(names, values)):
            if name not in triangles:  # a palpation view row
                ax.text(value + 0.3, y, f"{value:.1f} fps", va="center", fontsize=7)
                continue
            q = quality.get(name)
            label = f"{value:.1f} fps, {triangles[name] / 1e3:.0f}k triangles" + (
                f", IoU {q['iou']:.2f} vs full detail" if q and name not in (COCO_BAXTER, COCO_RGBD) else "")
            ax.text(value + 0.3, y, label, va="center", fontsize=7)
        ax.set_xlabel(f"frames per second, {SIZE[0]}x{SIZE[1]} headless, {renderer}")
        ax.set_title("CoCo display (GLManager) vs pyrender, same scene; the palpation app's view")
        ax.legend(loc="lower right", fontsize=8)
        ax.set_xlim(0, max(max(values) * 1.6, GOAL_FPS * 1.1))
        return fig

    return figure


def main() -> None:
    args = _report.parser("bench_display", __doc__.splitlines()[0]).parse_args()
    logging.getLogger("coco.transforms").setLevel(logging.ERROR)  # the recording names gripper-less joints
    poses, frames = motion(), rgbd_frames()
    scenes = {COCO_BAXTER: CocoScene("baxter", True, False), COCO_RGBD: CocoScene("baxter_rgbd", True, True),
              COCO_AUTO: CocoScene("baxter_auto", True, True, stride=0),
              COCO_LIGHT: CocoScene("light", True, True, stride=0, simplify=LIGHT),
              **{name: CocoScene(f"goal{i}", True, True, stride=0, simplify=LIGHT, spacing=spacing)
                 for i, (name, spacing) in enumerate(zip(COCO_GOALS, SPACINGS))},
              COCO_RGBD_ONLY: CocoScene("rgbd", False, True)}
    view = scenes[COCO_BAXTER].manager.views()[0].view
    variants: dict[str, Loop] = {name: scene.loop(poses, frames) for name, scene in scenes.items()
                                 if name != COCO_RGBD_ONLY}  # that scene measures the upload alone
    for run in variants.values():
        run(1)  # GLUrdf uploads its meshes at its first render
    images = {}
    for name in variants:
        with scenes[name].ctx:
            images[name] = scenes[name].frame(poses[0], frames[0])
    quality = {name: compare(images[name], images[COCO_BAXTER if name == COCO_BAXTER else COCO_RGBD])
               for name in variants}
    triangles = {name: scenes[name].triangles for name in variants}
    strides = {name: scenes[name].stride for name in variants}
    grid = 2 * (SIZE[0] - 1) * (SIZE[1] - 1)
    anchors: dict[str, PyrenderScene] = {}
    simplify = scenes[COCO_BAXTER].urdf.simplify  # type: ignore[union-attr]
    try:
        anchors = {PYR_BAXTER: PyrenderScene(True, False, view, simplify),
                   PYR_RGBD: PyrenderScene(True, True, view, simplify)}
    except Exception as error:  # pyrender missing or no EGL for it: CoCo rows alone
        print(f"pyrender does not run here ({type(error).__name__}: {error}); no anchor rows")
    overlap = {name: same_scene(scenes[coco], anchors[name], poses[0], frames[0])
               for coco, name in ((COCO_BAXTER, PYR_BAXTER), (COCO_RGBD, PYR_RGBD)) if name in anchors}
    for name, iou in overlap.items():
        if iou < MIN_OVERLAP:
            raise SystemExit(f"{name} and CoCo cover different pixels (IoU {iou:.3f} < {MIN_OVERLAP}): "
                             "not the same scene")
    for name, anchor in anchors.items():
        variants[name] = anchor.loop(poses, frames)
        triangles[name] = anchor.triangles + (grid if anchor.cpu is not None else 0)

    cpu = CpuSurface(*SIZE)
    copies = [np.empty_like(frames[0].color.data), np.empty_like(frames[0].depth.data)]
    uploads: dict[str, Loop] = {
        UPLOADS[0]: upload_loop(scenes[COCO_RGBD_ONLY], frames),
        UPLOADS[1]: lambda n: [cpu.build(frames[i % 2]) for i in range(n)],
        UPLOADS[2]: lambda n: [(np.copyto(copies[0], frames[i % 2].color.data),
                                np.copyto(copies[1], frames[i % 2].depth.data)) for i in range(n)],
    }
    palpation = {PALPATION_ROWS[0]: PalpationView(camera=True), PALPATION_ROWS[1]: PalpationView(camera=False)}
    palpation_loops = {name: view.loop(frames) for name, view in palpation.items()}
    for run in palpation_loops.values():
        run(1)
    with _report.LoadMeter() as load:
        frame_samples = measure(variants, repeats=REPEATS, target_s=TARGET_S)
        upload_samples = measure(uploads, repeats=REPEATS, target_s=0.1)
        palpation_samples = measure(palpation_loops, repeats=REPEATS, target_s=TARGET_S)
    repaints = {name: view.surface.repaints for name, view in palpation.items()}
    breakdown = {name: profile(variants[name], 10) for name in (COCO_BAXTER, COCO_RGBD, COCO_GOALS[0])}
    others = "n/a" if load.others is None else f"{load.others:.0%}"

    renderer = scenes[COCO_BAXTER].ctx.info["GL_RENDERER"]
    t1, r1 = frame_table(frame_samples, triangles, strides, quality, overlap, others, renderer)
    t2, r2 = upload_table(upload_samples)
    t3, r3 = profile_table(breakdown, renderer)
    t4, r4 = palpation_table(palpation_samples, repaints, others)
    _report.emit("bench_display", args, [t1, t2, t3, t4],
                 {"frames": r1, "uploads": r2, "profile_s_per_frame": r3, "palpation_view": r4, "renderer": renderer,
                  "overlap_iou": overlap, "others_cpu": load.others})
    _report.save_plot(args, draw(frame_samples, triangles, quality, renderer, palpation_samples))
    # pyrender's renderers are left to the end of the process: they share EGL's default display with
    # moderngl's contexts, and once one side has released its contexts the other cannot make its current.
    for closing in (*scenes.values(), *palpation.values()):
        closing.close()


if __name__ == "__main__":
    main()
