"""Components to route by stamps (FlowVR Render's pattern): a source of values that each carry a
bounding box as a user stamp, and a recorder of what each receiver got and with which stamp.

:class:`BoxEmitter` writes its count with the user stamps ``bbox`` (a unit box moving along x, as a
primitive moves through a scene) and ``part`` (its count, a whole number a ``Split`` can route by);
``Cull`` and ``Split`` filters on its connections decide which receiver gets what
(``config/stamp_routing.xml``, ``docs/flowvr.md``). :class:`StampRecorder` keeps, for each value it
took, the message's number, its user stamps and whether it came on a stamps-only connection (the
value is then the :class:`~coco_core.stamps.Stamp` itself), and writes that to ``out_dir/NAME.json`` when it
stops, so that a check in another process reads what happened.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..attributes import Attribute
from ..component import Component
from ..policy import NEW_DATA
from ..ports import InputPort, OutputPort
from ..stamps import Stamp
from .record import save_record


def box_of(count: int, span: int, size: float) -> tuple[float, float, float, float]:
    """The bounding box :class:`BoxEmitter` stamps its ``count``-th value with: ``size`` wide,
    starting at ``count % span`` along x, from 0 to ``size`` along y (x0 y0 x1 y1)."""
    x = float(count % span)
    return (x, 0.0, x + size, size)


class BoxEmitter(Component):
    """Each update writes its count on ``out`` with the user stamps ``bbox`` (:func:`box_of`) and
    ``part`` (the count); with ``stop_after`` it stops the application (naturally) after so many."""

    span = Attribute(int, 10, "the box starts at count % span along x", min=1)
    size = Attribute(float, 1.0, "the box's width and height", min=0.0)
    stop_after = Attribute(int, 0, "stop the application after this many writes; 0: never", min=0)

    out = OutputPort(int, "the number of updates before this one, stamped with its box")

    def init(self) -> None:
        self.count = 0

    def on_update(self) -> None:
        self.out.write(self.count, stamps={"bbox": box_of(self.count, self.span, self.size), "part": self.count})
        self.count += 1
        if self.count == self.stop_after and self.app is not None:
            self.app.request_stop(f"{self.name}: {self.count} values written")


class StampRecorder(Component):
    """Takes every value waiting on ``item`` and records it with its stamp (see the module)."""

    out_dir = Attribute(str, "", "a folder the record goes to when the recorder stops (NAME.json); empty: none")

    item = InputPort(object, event=True, doc="values, or stamps from a stamps-only connection")

    def init(self) -> None:
        self.got: list[dict[str, Any]] = []

    def on_update(self) -> None:
        while (read := self.item.read())[0] is NEW_DATA:
            value, stamp = read[1], self.item.stamp
            only = type(value) is Stamp
            self.got.append({"value": None if only else value, "stamps_only": only,
                             "seq": stamp.seq if stamp else -1, "source": stamp.source if stamp else "",
                             "user": dict(stamp.user) if stamp else {}})

    def on_stop(self) -> None:
        if self.out_dir:
            save_record(Path(self.out_dir) / f"{self.name}.json", self.got)
