"""SimulatedCamera: a camera that is not here, made of the display module's rendering of the scene.

Where an application needs a camera image of a scene the graph knows (a robot, a marker it holds)
and there is no camera, a GLManager renders the scene from the camera's pose, and this component
makes the rendering what a camera delivers: sensor noise (Gaussian, in grey levels), the pinhole
intrinsics of the rendering's field of view, the camera's frame and a stamp, on an output named and
typed as :class:`~.camera_reader.CameraReader`'s. A consumer (MarkerTracker, a recorder) cannot tell
it from a real camera, and the loop is closed: what the simulated camera sees moves with the graph.

The intrinsics are those of OpenGL's projection, whose pixel centres sit half a pixel inside the
image: ``fy = (height / 2) / tan(fov_y / 2)``, ``fx = fy`` (square pixels) and the principal point at
``((width - 1) / 2, (height - 1) / 2)`` in OpenCV's convention; no distortion. ``fov_y`` must be the
GLCameraManager's.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.ports import InputPort, OutputPort
from coco_core.stamps import Stamped, unstamped

from .image import CameraIntrinsics, Image, ImageFormat


def _eight_bit(image_format: ImageFormat) -> str | None:
    if ImageFormat(image_format).dtype != np.uint8:
        return f"a simulated camera delivers 8-bit images, not {ImageFormat(image_format).name}"
    return None


def render_intrinsics(width: int, height: int, fov_y_degrees: float, frame_id: str = "") -> CameraIntrinsics:
    """The pinhole intrinsics (OpenCV convention) of an OpenGL rendering with vertical field of view
    ``fov_y_degrees``."""
    focal = (height / 2.0) / math.tan(math.radians(fov_y_degrees) / 2.0)
    return CameraIntrinsics(width, height, focal, focal, (width - 1) / 2.0, (height - 1) / 2.0, frame_id=frame_id)


class SimulatedCamera(Component):
    """Rendered frames in, camera images out: noise, intrinsics, frame and stamp (see the module)."""

    fov_y = Attribute(float, 45.0, "vertical field of view of the rendering, degrees (the GLCameraManager's)",
                      min=1e-3, max=179.0)
    noise = Attribute(float, 2.0, "standard deviation of the sensor noise, grey levels (0: none)", min=0.0)
    format = Attribute(ImageFormat, ImageFormat.GRAY8, "format of the output images (a monochrome camera "
                       "by default: a fiducial tracker needs no colour, a recording a third of the bytes)",
                       check=_eight_bit)
    frame_id = Attribute(str, "camera", "the camera's frame, in the images and their intrinsics")
    seed = Attribute(int, -1, "seed of the noise (-1: a different one each run)")

    rendered = InputPort(Image | Stamped, event=True, doc="the display's frames (GLManager.color)")
    image = OutputPort(Stamped, "Stamped(Image): each frame in `format`, noisy, with intrinsics, stamped "
                       "with the rendering's time")
    camera_info = OutputPort(CameraIntrinsics, "the intrinsics, once per image (as a ROS camera_info topic)")

    def init(self) -> None:
        self.frames = 0

    def on_config(self) -> None:
        self._random = np.random.default_rng(None if self.seed < 0 else self.seed)
        self._intrinsics: CameraIntrinsics | None = None

    def on_update(self) -> None:
        for value in self.rendered.read_all():
            rendered, stamp = unstamped(value)
            image = self.capture(rendered)
            self.frames += 1
            assert image.intrinsics is not None
            self.camera_info.write(replace(image.intrinsics, stamp=image.stamp))  # as its image's, in ROS
            self.image.write(Stamped(image, stamp) if stamp is not None else Stamped(image))

    def capture(self, rendered: Image) -> Image:
        """One rendered frame as the camera delivers it."""
        height, width = rendered.data.shape[:2]
        intrinsics = self._intrinsics
        if intrinsics is None or (intrinsics.width, intrinsics.height) != (width, height):
            intrinsics = self._intrinsics = render_intrinsics(width, height, self.fov_y, self.frame_id)
        pixels = rendered.to(self.format).data
        if self.noise > 0:
            noisy = pixels + self._random.normal(0.0, self.noise, pixels.shape)  # float: no wrap-around
            pixels = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
        return Image(pixels, self.format, rendered.stamp, self.frame_id, intrinsics)
