"""ImageConverter: a filter that hands on every image in the one format its readers asked for.

A consumer that wants, say, GRAY8 from a YUYV camera connects through this component instead of
converting in its own ``on_update``; the conversion is done once per image (``Image.to`` remembers
it) however many readers the output has. Stamps pass through unchanged so that latency is still
measured from the acquisition.
"""

from __future__ import annotations

from coco_core.attributes import Attribute
from coco_core.component import Component
from coco_core.ports import InputPort, OutputPort
from coco_core.stamps import Stamped, unstamped

from .image import Image, ImageFormat


class ImageConverter(Component):
    """Converts each incoming image (or ``Stamped`` image) to ``format`` with OpenCV."""

    format = Attribute(ImageFormat, ImageFormat.BGR8, "the format of the output images")
    depth_scale = Attribute(float, 1000.0, "DEPTH16 units per metre, for depth <-> depth", min=1e-9)

    image = InputPort(Image | Stamped, event=True, doc="images in any format, optionally Stamped")
    converted = OutputPort(Image | Stamped, doc="the same images in `format`, with the input's stamp")

    def on_update(self) -> None:
        for value in self.image.read_all():
            image, stamp = unstamped(value)
            out = image.to(self.format, self.depth_scale)
            self.converted.write(out if stamp is None else Stamped(out, stamp))
