"""Shared memory between the processes of one application: the channels of the process level.

:class:`Arena` (the launcher's) makes a segment per connection between processes before the children
start and unlinks them all at the end; :func:`sweep` removes what a killed launcher left. A value
connection is a ring (:mod:`.channel`), a pooled one a pool of frame slots (:mod:`.frames`).
"""

from __future__ import annotations

import itertools

from ..policy import ConnectionPolicy
from .channel import ChannelError, ChannelSpec, ChannelStats, ShmReader, ShmWriter, layout, ring_size
from .frames import HEADER, NEWEST, SLOTS, ShmFrameNotifier, ShmFramePool, ShmPoolReader, control_size
from .segment import Segment, leftovers, segment_name, sweep

FRAME_SLOTS = 4
"""Slots of a pooled channel between processes (one written, one or two read, one spare)."""

__all__ = ["Arena", "ChannelError", "ChannelSpec", "ChannelStats", "ShmFrameNotifier", "ShmFramePool",
           "ShmPoolReader", "ShmReader", "ShmWriter", "leftovers", "sweep"]


class Arena:
    """Every segment of one launch, named ``coco.<launch>.<n>``; :meth:`close` unlinks them all."""

    def __init__(self, launch: str) -> None:
        self.launch = launch
        self._numbers = itertools.count()
        self.specs: list[ChannelSpec] = []

    def channel(self, policy: ConnectionPolicy, label: str, *, frames: bool = False,
                capacity: int | None = None) -> ChannelSpec:
        """Make the segment of one connection between processes (zeroed) and describe it."""
        name = segment_name(self.launch, next(self._numbers))
        if frames:
            spec = ChannelSpec(name, label, policy, FRAME_SLOTS, 0, frames=True)
            segment = Segment(name, control_size(FRAME_SLOTS))
            header = segment.view[:HEADER].cast("q")
            header[SLOTS], header[NEWEST] = FRAME_SLOTS, -1
            header.release()
        else:
            slots, size = layout(policy, capacity)
            spec = ChannelSpec(name, label, policy, slots, size)
            segment = Segment(name, ring_size(slots, size))
        segment.close()
        self.specs.append(spec)
        return spec

    def close(self) -> None:
        """Unlink every segment of the launch (frames' pixel segments too)."""
        sweep(self.launch)

