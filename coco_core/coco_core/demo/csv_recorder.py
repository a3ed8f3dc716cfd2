"""A sink that records stamped values to a CSV file; nothing written is lost on stop."""

from __future__ import annotations

import csv
import time
from pathlib import Path
from typing import IO

from ..attributes import Attribute
from ..component import Component
from ..ports import InputPort
from ..stamps import Stamped


class CsvRecorder(Component):
    """Appends ``seq, source, stamp_s, value, latency_ms`` rows; flushes every update and on stop."""

    path = Attribute(Path, Path("coco_record.csv"), "output file; its folder is created")

    values = InputPort(Stamped, doc="values to record")

    def on_config(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file: IO[str] = self.path.open("w", newline="")
        self._writer = csv.writer(self._file)
        self._writer.writerow(["seq", "source", "stamp_s", "value", "latency_ms"])
        self.rows = 0

    def on_update(self) -> None:
        samples = self.values.read_all()
        if not samples:
            return
        now = time.perf_counter()
        for sample in samples:
            stamp = sample.stamp
            self._writer.writerow([stamp.seq, stamp.source, f"{stamp.time:.6f}", f"{sample.value:.6f}",
                                   f"{(now - stamp.time) * 1e3:.3f}"])
            self.record_latency(stamp)
        self.rows += len(samples)
        self._file.flush()

    def on_stop(self) -> None:
        # Whatever arrived since the last update is still recorded.
        self.on_update()
        self._file.close()
