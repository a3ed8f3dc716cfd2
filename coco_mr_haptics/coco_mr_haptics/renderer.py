"""HapticRenderer and the renderers it owns: one 1 kHz activity, forces combined.

A *surface renderer* (HapticImplicitSurf, HapticCloud) turns a device position into a force through
its own proxy. It is normally a peer of a :class:`HapticRenderer`, which reads the device once per
cycle, brings its position into the renderer's frame of the transformation graph (the device's
workspace is a frame: calibrating a device is a registration), asks every peer for its force,
combines them and sends the result back in the workspace frame. A surface renderer scheduled on its
own (no owner) does the same for itself, with its own ``device``/``force`` ports.

The stiffness, damping, friction and force limit of each renderer are attributes: ``set_attribute``
changes them between two haptic cycles.

Whatever the scene, the material or the device sends, no non-finite number reaches a device: a
device state with a NaN or an infinity is refused (counted in the profile's ``refused`` column, the
proxies left where they were, zero force sent), and a renderer whose force is not finite (an infinite
stiffness, a scene that overflowed) contributes nothing that cycle, its proxy starts afresh and the
fault is counted (:attr:`SurfaceRenderer.force_faults`, the sample's ``fault``, the recorder's
summary).
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import ExtrapolationError, HapticDeviceError, SetupError, TransformError
from coco_core.policy import NO_DATA
from coco_core.ports import InputPort, OutputPort
from coco_core.transforms import se3
from coco_core.transforms.samples import FramePose

from .proxy import GodObject, Material
from .types import HapticDeviceState, HapticForce, HapticSample, Vector

log = logging.getLogger("coco")

_ZERO = (0.0, 0.0, 0.0)


def _finite(*values: float) -> bool:
    """True when every value is finite (their sum is NaN or infinite otherwise, or when it
    overflows: a force or a position that large is a fault all the same)."""
    return math.isfinite(sum(values))


class FrameLink:
    """A frame of the transformation graph (the device's workspace, a cloud's camera) seen from the
    render frame: points and vectors mapped both ways.

    A cached graph lookup costs ~0.1 us; the rotation is unpacked into floats only when the graph
    returns a new array (the graph caches its result until an edge on the path changes)."""

    def __init__(self, component: Component, render_frame: str, frame: str) -> None:
        self.component = component
        self.render_frame, self.frame = render_frame, frame
        self._seen: np.ndarray | None = None
        self.r: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
        self.t = _ZERO

    def refresh(self) -> None:
        if not self.frame or self.frame == self.render_frame:
            return
        pose = self.component.transform_graph.lookup(self.render_frame, self.frame)
        if pose is not self._seen:
            self._seen = pose
            self.r = tuple(float(v) for v in pose[:3, :3].reshape(-1))
            self.t = (float(pose[0, 3]), float(pose[1, 3]), float(pose[2, 3]))

    @property
    def joined(self) -> bool:
        """Whether the frame was ever found from the render frame (always, for the render frame)."""
        return not self.frame or self.frame == self.render_frame or self._seen is not None

    def to_render(self, v: Vector, point: bool) -> Vector:
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = self.r
        x, y, z = v
        tx, ty, tz = self.t if point else _ZERO
        return (r00 * x + r01 * y + r02 * z + tx, r10 * x + r11 * y + r12 * z + ty,
                r20 * x + r21 * y + r22 * z + tz)

    def read(self, port: InputPort, force: OutputPort) -> tuple[HapticDeviceState, Vector, Vector] | None:
        """The newest device state on ``port`` with its position and velocity in the render frame;
        None before the first, and None once zero force was sent on ``force`` for a state with a
        non-finite number (refused and counted: rendering it would leave every proxy NaN for good)."""
        status, state = port.read()
        if status is NO_DATA:
            return None
        self.refresh()
        position, velocity = self.to_render(state.position, True), self.to_render(state.velocity, False)
        if not _finite(*position, *velocity):
            self.component.record_refusal("a device state", HapticDeviceError(
                f"non-finite device state: position {state.position}, velocity {state.velocity} "
                f"(in frame {self.render_frame!r}: {position}, {velocity}); zero force sent"))
            force.write(HapticForce(_ZERO, state.stamp))
            return None
        return state, position, velocity

    def to_frame(self, v: Vector) -> Vector:
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = self.r
        x, y, z = v
        return (r00 * x + r10 * y + r20 * z, r01 * x + r11 * y + r21 * z, r02 * x + r12 * y + r22 * z)


class SurfaceRenderer(Component):
    """Base of the renderers a HapticRenderer owns: a proxy, a material, one force per cycle."""

    stiffness = Attribute(float, 800.0, "N/m between device and proxy", min=0.0)
    damping = Attribute(float, 1.0, "N s/m along the contact normal (>= stiffness x period / 2 keeps "
                        "the contact passive)", min=0.0)
    static_friction = Attribute(float, 0.0, "static friction coefficient (the cone the proxy sticks in)",
                                min=0.0)
    dynamic_friction = Attribute(float, 0.0, "dynamic friction coefficient (the cone a sliding proxy "
                                 "trails on); at most static_friction", min=0.0)
    max_force = Attribute(float, 8.0, "N: this renderer's force is clamped to it", min=0.0)
    max_slide = Attribute(float, 4e-4, "m per sliding sub-step of the proxy: below half the thinnest "
                          "wall", min=1e-6)
    frame = Attribute(str, "world", "frame of the transformation graph the surface is described in "
                      "(alone; as a peer, the owner's frame)")
    device_frame = Attribute(str, "", "the device's workspace frame (alone; \"\": the same as frame)")

    device = InputPort(HapticDeviceState, doc="device state, when scheduled alone")
    force = OutputPort(HapticForce, doc="force on the device, when scheduled alone")

    def __init__(self, name: str | None = None, **attributes: object) -> None:
        self._material_changed = True
        super().__init__(name, **attributes)

    def set_attribute_now(self, name: str, value: object) -> None:
        super().set_attribute_now(name, value)
        self._material_changed = True

    def material(self) -> Material:
        if self.dynamic_friction > self.static_friction:
            raise SetupError(f"{self.name}: dynamic_friction ({self.dynamic_friction}) must not exceed "
                             f"static_friction ({self.static_friction})")
        return Material(self.stiffness, self.damping, self.static_friction, self.dynamic_friction,
                        self.max_force, self.max_slide)

    @property
    def render_frame(self) -> str:
        owner = self.owner
        return owner.frame if isinstance(owner, HapticRenderer) else self.frame

    def on_config(self) -> None:
        self._workspace = FrameLink(self, self.frame, self.device_frame)
        self.proxy_object: GodObject | None = None
        self.force_faults = 0
        """Cycles whose force was not finite: sent as zero, the proxy restarted."""

    def contact_force(self) -> Vector | None:
        """The force of the last :meth:`render` in contact; None when it is not finite (counted as a
        fault, the proxy restarted so that the next cycle starts clean)."""
        god = self.proxy_object
        assert god is not None  # render() returned True: it has one
        force = god.force
        if _finite(*force):
            return force
        self.force_faults += 1
        if self.force_faults == 1:
            log.error("%s: non-finite force %s (stiffness %g, damping %g, depth %g): zero force sent instead; "
                      "further faults are counted (force_faults, the recorder's summary)", self.name, force,
                      self.stiffness, self.damping, god.depth)
        god.reset()
        return None

    def refresh_material(self) -> None:
        """Apply changed attributes to the proxy (between two cycles)."""
        if self._material_changed and self.proxy_object is not None:
            self.proxy_object.set_material(self.material())
            self._material_changed = False

    def render(self, x: float, y: float, z: float, vx: float, vy: float, vz: float) -> bool:
        """One haptic step for the device at ``(x, y, z)`` in the render frame; True in contact.
        The force, proxy and depth are then on :attr:`proxy_object`."""
        raise NotImplementedError

    @property
    def ready(self) -> bool:
        """Whether there is a surface to render (a HapticCloud has none before its first structure)."""
        return True

    def prepare(self) -> None:
        """Read this renderer's own inputs before a cycle (a new structure, a moved frame)."""

    def on_update(self) -> None:
        """Apply changed attributes and read own inputs; alone, also read the device, render and
        write the force (as a peer, the owner calls ``render`` next)."""
        self.refresh_material()
        self.prepare()
        if isinstance(self.owner, HapticRenderer):
            return
        reading = self._workspace.read(self.device, self.force)
        if reading is None:
            return
        state, (x, y, z), (vx, vy, vz) = reading
        force = self.contact_force() if self.render(x, y, z, vx, vy, vz) else _ZERO
        self.force.write(HapticForce(self._workspace.to_frame(force or _ZERO), state.stamp))


COMBINE = ("sum", "first")


class HapticRenderer(Component):
    """Owns surface renderers (peers) in one haptic activity and combines their forces.

    ``combine``: ``sum`` adds every renderer's force (several objects touched at once); ``first``
    takes the first renderer in contact in peer order (layered materials: a coating over a body).
    The sum is clamped to ``max_force`` (the device's limit).
    """

    manages_peers = True

    frame = Attribute(str, "world", "frame of the transformation graph the peers' surfaces are in")
    device_frame = Attribute(str, "", "the device's workspace frame (\"\": the same as frame)")
    combine = Attribute(str, "sum", "how peers' forces combine: sum or first (layered)", choices=COMBINE)
    max_force = Attribute(float, 8.0, "N: the combined force is clamped to it", min=0.0)

    device = InputPort(HapticDeviceState, doc="the device's state (workspace frame)")
    force = OutputPort(HapticForce, doc="the force on the device (workspace frame)")
    sample = OutputPort(HapticSample, doc="one record per cycle, in the render frame (for HapticRecorder)")
    penetration = OutputPort(float, "m: how deep the device is inside the surfaces this cycle (0 out of contact): "
                             "what a display colours the hand by (UpdateColor.value)")
    proxy = OutputPort(FramePose, "the proxy's position in the render frame (the device's where it is free): "
                       "where a display draws the contact point (GLEntity.pose)")
    proxy_force = OutputPort(tuple, "N: the force on the device in the render frame, applied at the proxy: "
                             "what a display draws as an arrow (UpdateVector.vector)")

    def on_config(self) -> None:
        self.renderers = [peer for peer in self.peers if isinstance(peer, SurfaceRenderer)]
        others = [peer.name for peer in self.peers if not isinstance(peer, SurfaceRenderer)]
        if others:
            raise SetupError(f"{self.name}: peers {', '.join(others)} are not surface renderers "
                             "(HapticImplicitSurf, HapticCloud)")
        self._workspace = FrameLink(self, self.frame, self.device_frame)
        self.force_faults = 0
        """Cycles in which a renderer's force or the combined force was not finite (zero sent instead)."""
        self.unjoined_cycles = 0
        """Cycles in which the device's workspace was not yet joined to the render frame."""

    def _unjoined(self, error: TransformError | ExtrapolationError) -> None:
        """The device's workspace frame is not joined to the render frame yet (a calibration, such as
        the palpation's touch on a marker, has not run): nothing can be rendered where the device
        is, so the force is zero and no sample is written, until the graph joins them."""
        if not self.unjoined_cycles:
            log.info("%s: the device's workspace %s is not joined to %s yet (%s): zero force until it is",
                     self.name, self.device_frame, self.frame, error)
        self.unjoined_cycles += 1
        self.force.write(HapticForce(_ZERO, time.perf_counter()))

    def on_stop(self) -> None:
        if self.unjoined_cycles and not self._workspace.joined:
            message = (f"{self.name}: the device's workspace {self.device_frame} was never joined to {self.frame}: "
                       f"{self.unjoined_cycles} haptic cycles rendered nothing")
            log.error("%s", message)
            if self.app is not None:
                self.app.report_damage(message)

    def on_update(self) -> None:
        workspace = self._workspace
        try:
            reading = workspace.read(self.device, self.force)
        except (TransformError, ExtrapolationError) as error:  # no path yet, or an edge on it without a value
            self._unjoined(error)
            return
        if reading is None:
            return
        state, (x, y, z), (vx, vy, vz) = reading
        fx = fy = fz = depth = 0.0
        proxy = (x, y, z)
        touching = ""
        fault = False
        first = self.combine == "first"
        for renderer in self.renderers:
            renderer.step()  # its own inputs (a new cloud structure, a moved frame) and attributes
            if not renderer.enabled or not renderer.render(x, y, z, vx, vy, vz):
                continue
            force = renderer.contact_force()
            if force is None:
                fault = True
                continue
            god = renderer.proxy_object
            assert god is not None  # it gave a force
            fx, fy, fz = fx + force[0], fy + force[1], fz + force[2]
            depth = max(depth, god.depth)
            if not touching:
                touching, proxy = renderer.name, god.proxy
                if first:
                    break
        unready = "" if all(r.ready for r in self.renderers) else ",".join(
            r.name for r in self.renderers if not r.ready)
        magnitude = math.sqrt(fx * fx + fy * fy + fz * fz)
        if magnitude > self.max_force:
            scale = self.max_force / magnitude
            fx, fy, fz = fx * scale, fy * scale, fz * scale
        out = workspace.to_frame((fx, fy, fz))
        if not _finite(*out):  # finite forces that overflowed when summed or turned, an infinite max_force
            fault, out, (fx, fy, fz) = True, _ZERO, _ZERO
        self.force_faults += fault
        self.force.write(HapticForce(out, state.stamp))
        self.sample.write(HapticSample(time.perf_counter(), (x, y, z), proxy, (fx, fy, fz), bool(touching),
                                       touching, depth, unready, fault))
        self.penetration.write(depth)
        if self.proxy.connections:  # the pose is built only for a display that draws it
            self.proxy.write(FramePose(self.frame, "proxy", se3.make(translation=proxy)))
        self.proxy_force.write((fx, fy, fz))
