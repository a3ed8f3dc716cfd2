"""Writing /tf and /tf_static into the transformation graph, without echoes.

/tf carries samples of moving frames: each transform becomes a sample of a *dynamic* edge
``header.frame_id -> child_frame_id`` at its header stamp (the edge is created on its first
sample). /tf_static carries fixed frames: each becomes a *static* edge, whose value a later static
message may replace (a new calibration); a static broadcaster re-sends its whole set whenever it
adds one, so receiving a known transform again changes nothing.

The echo rule: a transform whose child frame this bridge broadcasts itself is not ingested. That
drops the bridge's own messages when they come back from DDS (a node receives what it publishes),
and it keeps the graph the single authority of the frames it broadcasts, as tf2 wants one
publisher per child frame. Such transforms are counted (``echoes``), not reported as errors.

A transform that the graph cannot take (its edge is a URDF joint or an axis edge, or it writes a
static edge on /tf or a dynamic one on /tf_static) is counted and logged once per edge; the others
of the message are still ingested.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterable

from coco_core.transforms.graph import TransformGraph
from coco_core.transforms.samples import TransformSample

from .selection import Pair

log = logging.getLogger("coco.tf")


class TFIngest:
    """Writes received transforms into ``graph``; thread-safe (subscriptions may run in parallel)."""

    def __init__(self, graph: TransformGraph, prefix: str = "", owner: str = "tf",
                 broadcast: Callable[[], frozenset[str]] = frozenset) -> None:
        self.graph = graph
        self.prefix = prefix
        self.owner = owner
        self.broadcast = broadcast
        """The child frames this bridge broadcasts now (read at every message: the set can grow)."""
        self._lock = threading.Lock()
        self._ingested: set[Pair] = set()
        self._reported: set[Pair] = set()
        self.counts = {"received": 0, "ingested": 0, "echoes": 0, "rejected": 0}

    def ingested(self, pair: Pair) -> bool:
        """Whether the edge ``pair`` (graph names, prefix included) came from ROS."""
        return pair in self._ingested

    def _names(self, sample: TransformSample) -> Pair:
        return self.prefix + sample.parent, self.prefix + sample.child

    def dynamic(self, samples: Iterable[TransformSample]) -> None:
        """Samples received on /tf: dynamic edges at their stamps."""
        for sample in samples:
            pair = self._accept(sample)
            if pair is not None:
                self._write(pair, lambda: self.graph.set_transform(*pair, sample.transform, sample.stamp))

    def static(self, samples: Iterable[TransformSample]) -> None:
        """Samples received on /tf_static: static edges, added or (when their value changed) replaced."""
        for sample in samples:
            pair = self._accept(sample)
            if pair is not None:
                self._write(pair, lambda: self.graph.place_static(*pair, sample.transform))

    def _accept(self, sample: TransformSample) -> Pair | None:
        pair = self._names(sample)
        with self._lock:
            self.counts["received"] += 1
            if pair[1] in self.broadcast():
                self.counts["echoes"] += 1
                return None
            # An edge that ROS creates is marked before the write, so that a bridge refreshing its
            # broadcast set after the structure change already sees it as ingested. An edge the graph
            # had already (a tracker's, a calibration) stays the graph's own.
            if pair not in self._ingested and not self._exists(pair):
                self._ingested.add(pair)
        return pair

    def _exists(self, pair: Pair) -> bool:
        try:
            self.graph.edge(*pair)
        except LookupError:
            return False
        return True

    def _write(self, pair: Pair, write: Callable[[], object]) -> None:
        try:
            write()
        except (LookupError, ValueError) as error:
            with self._lock:
                self.counts["rejected"] += 1
                first = pair not in self._reported
                self._reported.add(pair)
            if first:
                log.error("%s: cannot write the transform %s -> %s from ROS into the transformation graph: %s "
                          "(further ones of this edge are counted, not logged)", self.owner, *pair, error)
            return
        with self._lock:
            self.counts["ingested"] += 1
