"""A sink that records numbers and their stamps to a CSV file; nothing written is lost on stop."""

from __future__ import annotations

import csv
import time
from pathlib import Path
from typing import IO

from ..attributes import Attribute
from ..component import Component
from ..ports import InputPort
from ..stamps import Stamped, unstamped


class CsvRecorder(Component):
    """Appends ``seq, source, stamp_s, value, latency_ms`` rows; flushes every update and on stop.

    The stamp of a row is its value's origin (:attr:`InputPort.origin
    <coco_core.ports.InputPort.origin>`): a ``Stamped`` value's own, a plain number's message stamp
    (its number on the writing port, that port, the time of the write), so plain numbers are
    recorded, and their latency profiled, as stamped ones are."""

    path = Attribute(Path, Path("coco_record.csv"), "output file; its folder is created")

    values = InputPort(Stamped | float | int, doc="numbers to record, plain or Stamped")

    def on_config(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file: IO[str] = self.path.open("w", newline="")
        self._writer = csv.writer(self._file)
        self._writer.writerow(["seq", "source", "stamp_s", "value", "latency_ms"])
        self.rows = 0

    def on_update(self) -> None:
        samples = self.values.read_all_origins()
        if not samples:
            return
        now = time.perf_counter()
        for sample, stamp in samples:
            value = unstamped(sample)[0]
            if stamp is None:  # a number pushed into the connection without a port: no stamp to give
                self._writer.writerow(["", "", "", f"{value:.6f}", ""])
                continue
            self._writer.writerow([stamp.seq, stamp.source, f"{stamp.time:.6f}", f"{value:.6f}",
                                   f"{(now - stamp.time) * 1e3:.3f}"])
            self.record_latency(stamp)
        self.rows += len(samples)
        self._file.flush()

    def on_stop(self) -> None:
        # Whatever arrived since the last update is still recorded.
        self.on_update()
        self._file.close()
