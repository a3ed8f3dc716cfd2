"""sensor_msgs/CompressedImage -> Image: image_transport's ``compressed`` (JPEG, PNG) gives what the raw
Image converter gives for the same pixels; ``compressedDepth`` (12-byte header, then PNG or RVL) gives
the depth values as they were; damaged or oversized data is refused naming what was found."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from coco_core.errors import MessageError
from coco_mr_vision.image import ImageFormat
from coco_ros.convert import converter_for
from sensor_msgs.msg import CompressedImage
from sensor_msgs.msg import Image as ImageMsg
from std_msgs.msg import Header

cv2 = pytest.importorskip("cv2")

compressed = converter_for("sensor_msgs/msg/CompressedImage")
raw = converter_for("sensor_msgs/msg/Image")
HEADER = Header(frame_id="camera_color_optical_frame")
HEADER.stamp.sec, HEADER.stamp.nanosec = 12, 500_000_000


def rgb_pattern(width: int = 32, height: int = 24) -> np.ndarray:
    y, x = np.mgrid[0:height, 0:width]
    return np.stack([x * 8, y * 10, (x + y) * 4], axis=-1).astype(np.uint8)


def message(fmt: str, data: bytes) -> CompressedImage:
    return CompressedImage(header=HEADER, format=fmt, data=data)


@pytest.mark.parametrize("encoding", ["rgb8", "bgr8"])
def test_png_gives_what_the_raw_image_gives(encoding: str):
    pixels = rgb_pattern()
    as_bgr = pixels[..., ::-1] if encoding == "rgb8" else pixels  # imencode takes BGR
    ok, png = cv2.imencode(".png", np.ascontiguousarray(as_bgr))
    image = compressed.to_coco(message(f"{encoding}; png compressed bgr8", png.tobytes()))
    expected = raw.to_coco(ImageMsg(header=HEADER, height=24, width=32, encoding=encoding, step=96,
                                    data=pixels.tobytes()))
    assert image.format is expected.format and np.array_equal(image.data, expected.data)
    assert (image.stamp, image.frame_id) == (12.5, "camera_color_optical_frame")


def test_jpeg_and_the_old_bare_format_names():
    pixels = np.full((16, 16, 3), 128, np.uint8)
    ok, jpeg = cv2.imencode(".jpg", pixels)
    image = compressed.to_coco(message("jpeg", jpeg.tobytes()))
    assert image.format is ImageFormat.BGR8 and np.abs(image.data.astype(int) - 128).max() <= 2
    gray = np.arange(256, dtype=np.uint16).reshape(16, 16) * 200
    ok, png = cv2.imencode(".png", gray)
    image = compressed.to_coco(message("mono16; png compressed mono16", png.tobytes()))
    assert image.format is ImageFormat.GRAY16 and np.array_equal(image.data, gray)


def depth_pattern() -> np.ndarray:
    depth = (np.arange(24 * 32, dtype=np.uint16).reshape(24, 32) * 7 + 400).astype(np.uint16)
    depth[5:9, 3:20] = 0  # holes, as a depth camera has
    return depth


def test_compressed_depth_png_gives_the_depth_values():
    depth = depth_pattern()
    ok, png = cv2.imencode(".png", depth)
    image = compressed.to_coco(message("16UC1; compressedDepth png", bytes(12) + png.tobytes()))
    assert image.format is ImageFormat.DEPTH16 and np.array_equal(image.data, depth)


def test_compressed_depth_32fc1_is_quantised_inverse_depth():
    a, b = 100.0, 10.0  # image_transport's depth_quantization and max range make these
    metres = np.array([[0.5, 1.0], [2.0, 0.0]], np.float32)
    with np.errstate(divide="ignore"):
        inverse = np.where(metres > 0, a / np.where(metres > 0, metres, 1) + b, 0).astype(np.uint16)
    ok, png = cv2.imencode(".png", inverse)
    image = compressed.to_coco(message("32FC1; compressedDepth png", struct.pack("<iff", 0, a, b) + png.tobytes()))
    assert image.format is ImageFormat.DEPTH32F
    assert np.allclose(image.data[:, :][metres > 0], metres[metres > 0]) and np.isnan(image.data[1, 1])


def rvl(depth: np.ndarray) -> bytes:
    """Wilson's CompressRVL, as image_transport's compressedDepth ``rvl`` writes it (after its width and height)."""
    nibbles: list[int] = []

    def vle(value: int) -> None:
        while True:
            nibble = value & 0x7
            value >>= 3
            nibbles.append(nibble | (0x8 if value else 0))
            if not value:
                return

    values = depth.reshape(-1).astype(int).tolist()
    index, previous = 0, 0
    while index < len(values):
        zeros = 0
        while index < len(values) and values[index] == 0:
            zeros, index = zeros + 1, index + 1
        vle(zeros)
        run = 0
        while index + run < len(values) and values[index + run] != 0:
            run += 1
        vle(run)
        for value in values[index:index + run]:
            delta = value - previous
            vle((delta << 1) ^ (delta >> 31))
            previous = value
        index += run
    nibbles += [0] * (-len(nibbles) % 8)
    words = [sum(n << (28 - 4 * k) for k, n in enumerate(nibbles[i:i + 8])) for i in range(0, len(nibbles), 8)]
    return struct.pack("<II", depth.shape[1], depth.shape[0]) + struct.pack(f"<{len(words)}I", *words)


def test_compressed_depth_rvl_gives_the_depth_values():
    depth = depth_pattern()
    depth[20, 30] = 60000  # a large jump down and up again: negative deltas
    image = compressed.to_coco(message("16UC1; compressedDepth rvl", bytes(12) + rvl(depth)))
    assert image.format is ImageFormat.DEPTH16 and np.array_equal(image.data, depth)


def test_damaged_and_oversized_data_is_refused_naming_it():
    ok, png = cv2.imencode(".png", depth_pattern())
    with pytest.raises(MessageError, match="cannot be decoded"):
        compressed.to_coco(message("16UC1; compressedDepth png", bytes(12) + png.tobytes()[:60]))
    with pytest.raises(MessageError, match="neither PNG nor JPEG"):
        compressed.to_coco(message("rgb8; jpeg compressed bgr8", b"GIF89a" + bytes(40)))
    huge = bytearray(png.tobytes())
    huge[16:24] = struct.pack(">II", 100_000, 100_000)
    with pytest.raises(MessageError, match="declares 100000x100000 pixels"):
        compressed.to_coco(message("16UC1; compressedDepth png", bytes(12) + bytes(huge)))
    with pytest.raises(MessageError, match="ends before its 32x24 pixels"):
        compressed.to_coco(message("16UC1; compressedDepth rvl", bytes(12) + rvl(depth_pattern())[:40]))
    with pytest.raises(MessageError, match="12-byte compressedDepth header"):
        compressed.to_coco(message("16UC1; compressedDepth png", b"\x00" * 5))
    ok, colour = cv2.imencode(".png", rgb_pattern())
    with pytest.raises(MessageError, match="one 16-bit channel"):
        compressed.to_coco(message("16UC1; compressedDepth png", bytes(12) + colour.tobytes()))
