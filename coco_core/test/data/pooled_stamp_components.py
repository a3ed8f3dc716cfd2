"""Components of the pooled frames' stamp tests (``test_pooled_stamps.py``): a source of pooled
frames that each carry user stamps (a box and a part number, as ``coco_core.demo.routing``'s
BoxEmitter writes) and an acquisition stamp of their own (``Slot.stamp``), and a recorder of the
frames a reader got with their stamps and origins. The launcher and its child processes import
them by ``module:Class`` (this folder is on their PYTHONPATH), so the same application runs in one
process or spread over several."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from coco_core import NEW_DATA, Attribute, Component, InputPort, PooledOutputPort, Slot, Stamp
from coco_core.demo.record import save_record
from coco_core.demo.routing import box_of

AGE = 0.25
"""Seconds between a frame's acquisition (its ``Slot.stamp``) and its write."""


class BoxFrameSource(Component):
    """Publishes frame ``count`` (4 int64 filled with it) with the user stamps ``bbox``
    (:func:`box_of`) and ``part`` (the count), its ``Slot.stamp`` an acquisition stamp ``AGE``
    seconds before the write, numbered ``count`` from the source ``sensor``; stops the application
    after ``stop_after`` frames. A frame no free slot could take is tried again at the next update."""

    stop_after = Attribute(int, 50, "stop the application after this many frames", min=1)
    frames = PooledOutputPort(slots=4)

    def init(self) -> None:
        self.count = 0

    def on_update(self) -> None:
        if self.count >= self.stop_after:
            return
        slot = self.frames.acquire((4,), np.int64)
        if slot is None:
            return
        slot.array[:] = self.count
        slot.stamp = Stamp(time.perf_counter() - AGE, self.count, "sensor")
        self.frames.write(slot, stamps={"bbox": box_of(self.count, 10, 1.0), "part": self.count})
        self.count += 1
        if self.count == self.stop_after and self.app is not None:
            self.app.request_stop(f"{self.name}: {self.count} frames written")


class FrameRecorder(Component):
    """Reads each new frame on ``frames`` and records its number (the pixels), its message stamp
    (number, source, user stamps) and whether its time and ``port.origin`` are the frame's own
    acquisition stamp; writes the record to ``out_dir/NAME.json`` when it stops."""

    out_dir = Attribute(str, "", "the folder the record goes to (NAME.json)")
    frames = InputPort(Slot, event=True)

    def init(self) -> None:
        self.got: list[dict[str, Any]] = []

    def on_update(self) -> None:
        while (read := self.frames.read())[0] is NEW_DATA:
            with read[1] as slot:
                stamp, origin = self.frames.stamp, self.frames.origin
                assert stamp is not None and origin is not None
                self.got.append({"value": int(slot.array[0]), "seq": stamp.seq, "source": stamp.source,
                                 "user": dict(stamp.user), "timed_from_acquisition": stamp.time == slot.stamp.time,
                                 "origin": [origin.seq, origin.source], "origin_is_own": origin == slot.stamp})

    def on_stop(self) -> None:
        if self.out_dir:
            save_record(Path(self.out_dir) / f"{self.name}.json", self.got)
