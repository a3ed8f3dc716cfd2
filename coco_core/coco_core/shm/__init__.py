"""Shared memory between the processes of one application: the channels of the process level.

:class:`Arena` (the launcher's) makes a segment per connection between processes (per pooled output,
whose one pool all its readers share) before the children start and unlinks them all at the end; :func:`sweep` removes what a killed launcher left. A value
connection is a ring (:mod:`.channel`), a pooled one a pool of frame slots (:mod:`.frames`); the
launch decides whether its rings take the locked path (:mod:`.ordering`).
"""

from __future__ import annotations

import itertools

from ..policy import ConnectionPolicy
from .channel import ChannelError, ChannelSpec, ChannelStats, ShmReader, ShmWriter, layout, ring_size
from .frames import HEADER, NEWEST, SLOTS, FrameStats, ShmFrameNotifier, ShmFramePool, ShmPoolReader, control_size
from .ordering import FORCE_LOCKED, rings_locked
from .segment import Segment, leftovers, segment_name, sweep

FLAGS = "flags"


def flags_name(spec: ChannelSpec) -> str:
    """The flags segment of the launch that made channel ``spec``."""
    return f"{spec.segment.rpartition('.')[0]}.{FLAGS}"


__all__ = ["Arena", "ChannelError", "ChannelSpec", "ChannelStats", "FORCE_LOCKED", "FrameStats", "ShmFrameNotifier",
           "ShmFramePool", "ShmPoolReader", "ShmReader", "ShmWriter", "Segment", "flags_name", "leftovers",
           "rings_locked", "sweep"]


class Arena:
    """Every segment of one launch, named ``coco.<launch>.<n>``; :meth:`close` unlinks them all."""

    def __init__(self, launch: str) -> None:
        self.launch = launch
        self._numbers = itertools.count()
        self.specs: list[ChannelSpec] = []
        self.locked = rings_locked()
        """Whether the launch's rings take the locked path (:mod:`.ordering`): decided here, once,
        so that every process of the launch follows its channels' descriptions."""

    def channel(self, policy: ConnectionPolicy, label: str, *, frames: bool = False,
                capacity: int | None = None, readers: int = 1) -> ChannelSpec:
        """Make the segment of one connection between processes (zeroed) and describe it. A frame
        pool has ``policy.size`` slots (the pooled output's own count) and a counter for each of its
        ``readers`` in other processes; each reader's connection is the spec with its own label and
        reader number (:func:`dataclasses.replace`)."""
        name = segment_name(self.launch, next(self._numbers))
        if frames:
            slots = max(2, policy.size)
            spec = ChannelSpec(name, label, policy, slots, 0, frames=True, readers=readers)
            segment = Segment(name, control_size(slots, readers))
            header = segment.view[:HEADER].cast("q")
            header[SLOTS], header[NEWEST] = slots, -1
            header.release()
        else:
            slots, size = layout(policy, capacity)
            spec = ChannelSpec(name, label, policy, slots, size, locked=self.locked)
            segment = Segment(name, ring_size(slots, size))
        segment.close()
        self.specs.append(spec)
        return spec

    def flags(self, count: int) -> str:
        """Make the launch's flags segment (``count`` words, zeroed): where a reader's process says
        whether a write wakes it, when only its built component knows (:mod:`coco_core.processes.channels`)."""
        name = segment_name(self.launch, FLAGS)
        Segment(name, 8 * count).close()
        return name

    def close(self) -> None:
        """Unlink every segment of the launch (frames' pixel segments too)."""
        sweep(self.launch)

