"""Conversions between every pair of image formats, with OpenCV only.

Each direct conversion is one OpenCV call (``cv2.cvtColor`` with the matching ``COLOR_*`` code,
or a scaling of depth); a pair with no direct code goes through the shortest chain of direct ones
(grey -> I420 goes through BGR, YUYV -> I420 through BGR), found once per pair and cached. So a
conversion costs what OpenCV costs, and its result is exactly what the same OpenCV calls give.

YUV follows OpenCV's convention (BT.601, limited range), the one V4L2 cameras and video codecs use.
GRAY16 <-> GRAY8 keeps the high byte (and replicates it back: 255 -> 65535). Depth converts only to
depth: DEPTH16 holds ``depth_scale`` units per metre (1000: millimetres), 0 where unknown; DEPTH32F
holds metres, NaN where unknown. Showing depth as colour is a display choice (``Image.to_rgb``).
"""

from __future__ import annotations

import functools
from collections import deque
from dataclasses import replace
from typing import Callable

import cv2
import numpy as np
from coco_core.errors import ConversionError

from .image import Image, ImageFormat, _as_format

Step = Callable[[np.ndarray], np.ndarray]

F = ImageFormat
_OPENCV_NAMES = {F.GRAY8: "GRAY", F.RGB8: "RGB", F.BGR8: "BGR", F.RGBA8: "RGBA", F.BGRA8: "BGRA"}
_COLOUR = (F.GRAY8, F.GRAY16, F.RGB8, F.BGR8, F.RGBA8, F.BGRA8, F.YUYV, F.I420)


def _cvt(code: int) -> Step:
    def step(data: np.ndarray) -> np.ndarray:
        return cv2.cvtColor(data, code)
    step.__name__ = f"cvtColor[{code}]"
    return step


def _gray16_to_gray8(data: np.ndarray) -> np.ndarray:
    return cv2.convertScaleAbs(data >> 8)


def _gray8_to_gray16(data: np.ndarray) -> np.ndarray:
    # OpenCV takes a scalar second operand; its stubs list arrays only
    return cv2.multiply(data.astype(np.uint16), 257, dtype=cv2.CV_16U)  # type: ignore[call-overload]


def _direct_steps() -> dict[tuple[ImageFormat, ImageFormat], Step]:
    """Every conversion OpenCV does in one call, keyed by (source, target)."""
    steps: dict[tuple[ImageFormat, ImageFormat], Step] = {}
    for source, a in _OPENCV_NAMES.items():
        for target, b in _OPENCV_NAMES.items():
            code = getattr(cv2, f"COLOR_{a}2{b}", None)
            if source is not target and code is not None:
                steps[source, target] = _cvt(code)
        if source is not F.GRAY8:
            steps[source, F.YUYV] = _cvt(getattr(cv2, f"COLOR_{a}2YUV_YUYV"))
            steps[source, F.I420] = _cvt(getattr(cv2, f"COLOR_{a}2YUV_I420"))
        steps[F.YUYV, source] = _cvt(getattr(cv2, f"COLOR_YUV2{a}_YUYV"))
        steps[F.I420, source] = _cvt(getattr(cv2, f"COLOR_YUV2{a}_I420"))
    steps[F.GRAY16, F.GRAY8] = _gray16_to_gray8
    steps[F.GRAY8, F.GRAY16] = _gray8_to_gray16
    return steps


_DIRECT = _direct_steps()


@functools.lru_cache(maxsize=None)
def conversion_path(source: ImageFormat, target: ImageFormat) -> tuple[ImageFormat, ...]:
    """The formats a conversion passes through, ``source`` first and ``target`` last.

    Breadth-first over the direct conversions, preferring BGR8 as the intermediate (OpenCV's own
    order) when several chains are equally short."""
    if source.is_depth or target.is_depth:
        if source.is_depth and target.is_depth:
            return (source, target) if source is not target else (source,)
        raise ConversionError(f"cannot convert {source.name} to {target.name}: depth converts only to depth "
                              f"(DEPTH16, DEPTH32F); use Image.to_rgb() to show depth as colour")
    order = sorted(_COLOUR, key=lambda f: f is not F.BGR8)
    previous: dict[ImageFormat, ImageFormat | None] = {source: None}
    queue = deque([source])
    while queue:
        here = queue.popleft()
        if here is target:
            break
        for nxt in order:
            if (here, nxt) in _DIRECT and nxt not in previous:
                previous[nxt] = here
                queue.append(nxt)
    path = [target]
    while previous[path[-1]] is not None:
        path.append(previous[path[-1]])  # type: ignore[arg-type]
    return tuple(reversed(path))


def convert_array(data: np.ndarray, source: ImageFormat | str, target: ImageFormat | str,
                  depth_scale: float = 1000.0) -> np.ndarray:
    """``data`` in ``source`` layout converted to ``target``; ``data`` itself when they are equal.

    ``depth_scale`` is DEPTH16 units per metre, used only between the two depth formats."""
    source, target = _as_format(source), _as_format(target)
    path = conversion_path(source, target)
    if source.is_depth and len(path) == 2:
        return _depth_to_depth(data, source, depth_scale)
    data = np.ascontiguousarray(data)
    for a, b in zip(path, path[1:]):
        data = _DIRECT[a, b](data)
    return data


def _depth_to_depth(data: np.ndarray, source: ImageFormat, depth_scale: float) -> np.ndarray:
    if not depth_scale > 0:
        raise ConversionError(f"depth_scale is DEPTH16 units per metre and must be > 0, got {depth_scale}")
    if source is F.DEPTH16:
        metres = data.astype(np.float32)
        metres *= np.float32(1.0 / depth_scale)
        metres[data == 0] = np.nan
        return metres
    units = np.nan_to_num(data, nan=0.0, posinf=0.0, neginf=0.0) * np.float32(depth_scale)
    # Rounded, and clipped to what 16 bits hold: depth beyond 65.535 m (at mm) is unknown, not wrapped.
    units = np.rint(units)
    units[(units < 0) | (units > 65535)] = 0
    return units.astype(np.uint16)


def convert(image: Image, target: ImageFormat | str, depth_scale: float = 1000.0) -> Image:
    """``image`` in ``target`` format, with its stamp, frame and intrinsics; ``image`` if already so."""
    target = _as_format(target)
    if image.format is target:
        return image
    return replace(image, data=convert_array(image.data, image.format, target, depth_scale), format=target)
