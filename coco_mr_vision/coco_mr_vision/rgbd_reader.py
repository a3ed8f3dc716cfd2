"""RgbdCameraReader: a periodic source of registered colour + depth frames from a back-end peer.

The back-end is a peer (:mod:`coco_mr_vision.rgbd_peers`): declared in the XML as the reader's one
peer with its own attributes, or made from the reader's ``backend`` and ``path`` attributes for the
common case. The reader asks the peer for one frame per activation, converts colour and depth to
the formats asked for (once, with OpenCV), stamps the frame (acquisition time, sequence, source)
and writes it. A recording that ends starts again with ``loop``, or stops the reader's output.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace

from coco_core import registry
from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.errors import CocoError, UnknownComponentError
from coco_core.ports import OutputPort
from coco_core.stamps import Stamp, Stamped

from .image import ImageFormat
from .rgbd import RGBDFrame
from .rgbd_peers import BACKENDS, RgbdPeer

log = logging.getLogger("coco.vision")


class RgbdCameraReader(Component):
    """Delivers one RGBDFrame per activation from its back-end peer."""

    manages_peers = True

    backend = Attribute(str, "", "tum, redwood, bag, realsense or topic when no peer is declared",
                        choices=("", *BACKENDS))
    path = Attribute(str, "", "folder, bag or device the made peer opens (its `path` attribute)")
    loop = Attribute(bool, False, "start a recording again at its end")
    color_format = Attribute(ImageFormat, ImageFormat.BGR8, "format of the colour images")
    depth_format = Attribute(ImageFormat, ImageFormat.DEPTH16, "DEPTH16 (units of the frame's depth_scale) "
                             "or DEPTH32F (metres)", choices=(ImageFormat.DEPTH16, ImageFormat.DEPTH32F))

    rgbd = OutputPort(Stamped, "Stamped(RGBDFrame): colour and depth of one instant, with intrinsics")

    def init(self) -> None:
        if self.backend and not self.peers:
            peer_class = self._backend_peer()
            attributes = {"path": self.path} if "path" in peer_class._attribute_decls else {}
            self.add_peer(peer_class(f"{self.name}.{self.backend}", **attributes))
        sources = [p for p in self.peers if isinstance(p, RgbdPeer)]
        if len(sources) != 1:
            raise CocoError(f"component {self.name} (RgbdCameraReader) needs exactly one RGB-D peer "
                            f"({', '.join(BACKENDS.values())} or another RgbdPeer) or a "
                            f"backend attribute ({', '.join(BACKENDS)}); it has {len(sources)}")
        self.source: RgbdPeer = sources[0]
        self.frames = 0
        """Frames delivered."""
        self.ended = False

    def _backend_peer(self) -> type[RgbdPeer]:
        """The peer class of ``backend``, by its registered name: the bag peer comes from coco_ros,
        which this package must not import (coco_ros depends on it)."""
        task = BACKENDS[self.backend]
        try:
            peer_class = registry.load(task)
        except UnknownComponentError as error:
            raise CocoError(f"component {self.name} (RgbdCameraReader): backend {self.backend!r} needs the "
                            f"{task} component, which no installed package provides ({error})") from None
        if not issubclass(peer_class, RgbdPeer):
            raise CocoError(f"component {self.name} (RgbdCameraReader): backend {self.backend!r} names {task}, "
                            "which is not an RgbdPeer")
        return peer_class

    def on_config(self) -> None:
        self._seq = 0

    def on_update(self) -> None:
        if self.ended:
            return
        frame = self.source.grab()
        if frame is None and self.source.exhausted and self.loop and self.source.rewind():
            frame = self.source.grab()
        if frame is None:
            if self.source.exhausted:
                self.ended = True
                log.info("%s: the recording ended after %d frames", self.name, self.frames)
            return
        now = time.perf_counter()
        self._seq += 1
        self.frames += 1
        self.rgbd.write(Stamped(self._in_formats(frame), Stamp(now, self._seq, self.name)))

    def _in_formats(self, frame: RGBDFrame) -> RGBDFrame:
        color = frame.color.to(self.color_format)
        depth = frame.depth.to(self.depth_format, frame.depth_scale)
        if color is frame.color and depth is frame.depth:
            return frame
        # Metres -> DEPTH16 is made at the frame's depth_scale, so that scale stays right either way.
        return replace(frame, color=color, depth=depth)
