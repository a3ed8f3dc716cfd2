"""A contact sheet: one picture of a recording, N evenly spaced frames in a grid, labelled.

A recording's length is unknown until it stops, so the sheet keeps thumbnails of every ``stride``-th
frame and doubles the stride whenever it holds four times the frames it will show: memory stays
bounded (at most ``4 N`` thumbnails plus the newest frame) however long the run, and at the end every
shown frame is within ``stride / 2`` frames (an eighth of the spacing or better) of its evenly spaced
ideal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from coco_core.errors import FileWriteError, SetupError


@dataclass(frozen=True)
class _Kept:
    index: int
    seconds: float | None
    picture: np.ndarray
    """A thumbnail, or for the newest frame the frame itself (thumbnailed only if shown)."""


class ContactSheet:
    """Collects frames (RGB arrays) as they are recorded and renders the sheet at the end."""

    def __init__(self, frames: int = 16, columns: int = 4, tile_width: int = 240) -> None:
        if frames < 1 or columns < 1 or tile_width < 8:
            raise SetupError(f"contact sheet: frames ({frames}) and columns ({columns}) must be >= 1, "
                             f"tile_width ({tile_width}) >= 8")
        self.frames, self.columns, self.tile_width = frames, columns, tile_width
        self.stride = 1
        self.kept: list[_Kept] = []
        self.newest: _Kept | None = None
        self._tile_size: tuple[int, int] | None = None

    def add(self, index: int, seconds: float | None, rgb: np.ndarray) -> None:
        """Offer frame ``index`` (recorded ``seconds`` after the first, if known); ``rgb`` is not copied
        and must not change afterwards (images on CoCo ports never do)."""
        if self._tile_size is None:
            height, width = rgb.shape[:2]
            self._tile_size = (self.tile_width, max(1, round(self.tile_width * height / width)))
        self.newest = _Kept(index, seconds, rgb)
        if index % self.stride:
            return
        self.kept.append(_Kept(index, seconds, self._thumbnail(rgb)))
        if len(self.kept) >= 4 * self.frames:
            self.stride *= 2
            self.kept = [kept for kept in self.kept if kept.index % self.stride == 0]

    def _thumbnail(self, rgb: np.ndarray) -> np.ndarray:
        assert self._tile_size is not None
        return cv2.resize(rgb, self._tile_size, interpolation=cv2.INTER_AREA)

    def chosen(self) -> list[_Kept]:
        """The frames shown: nearest to ``frames`` evenly spaced indices from the first to the newest."""
        if self.newest is None:
            return []
        candidates = list(self.kept)
        if candidates[-1].index != self.newest.index:
            candidates.append(self.newest)
        wanted = np.linspace(0, self.newest.index, min(self.frames, self.newest.index + 1))
        indices = np.array([kept.index for kept in candidates])
        picks = sorted({int(np.abs(indices - target).argmin()) for target in wanted})
        return [candidates[pick] for pick in picks]

    def render(self) -> np.ndarray | None:
        """The sheet as an RGB array (None before any frame): a grid of labelled thumbnails."""
        chosen = self.chosen()
        if not chosen or self._tile_size is None:
            return None
        tile_w, tile_h = self._tile_size
        columns = min(self.columns, len(chosen))
        rows = math.ceil(len(chosen) / columns)
        gap = 4
        sheet = np.full((rows * (tile_h + gap) + gap, columns * (tile_w + gap) + gap, 3), 32, np.uint8)
        for slot, kept in enumerate(chosen):
            picture = kept.picture if kept.picture.shape[:2] == (tile_h, tile_w) else self._thumbnail(kept.picture)
            y, x = gap + (slot // columns) * (tile_h + gap), gap + (slot % columns) * (tile_w + gap)
            tile = sheet[y:y + tile_h, x:x + tile_w]
            tile[...] = picture
            self._label(tile, f"#{kept.index}" + (f"  {kept.seconds:.2f} s" if kept.seconds is not None else ""))
        return sheet

    @staticmethod
    def _label(tile: np.ndarray, text: str) -> None:
        scale = max(0.3, tile.shape[1] / 600)
        (width, height), baseline = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
        bottom = tile.shape[0] - 3
        tile[max(0, bottom - height - 4):, :min(tile.shape[1], width + 6)] //= 3  # darken under the text
        cv2.putText(tile, text, (3, bottom - baseline // 2), cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), 1,
                    cv2.LINE_AA)

    def write(self, path: Path) -> bool:
        """Write the sheet as PNG; False when there was no frame."""
        sheet = self.render()
        if sheet is None:
            return False
        if not cv2.imwrite(str(path), sheet[..., ::-1]):
            raise FileWriteError(f"could not write the contact sheet {path}")
        return True
