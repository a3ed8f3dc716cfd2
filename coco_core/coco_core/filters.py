"""Filters on connections (FlowVR's): the coupling of two activities, chosen in the application file.

A FlowVR filter sits in a connection's path and sees its whole input buffer: it may hold messages
back, add some, drop some or pick one, which a module (that only sees the newest) cannot. Here a
filter *is* the connection's storage: a :class:`~coco_core.connections.Connection` whose ``push``
runs in the writer's thread and whose ``pop`` runs in the reader's, so a filter costs no thread of
its own. It reads the stamps of the messages it holds (:class:`~coco_core.stamps.Message`), never
their payload.

- :class:`PreSignal` starts with ``tokens`` messages, then forwards what comes in order: it boots a
  cycle (FlowVR's FilterPreSignal; Figure 1 b of the FlowVR paper: the consumer's ``endit`` back to
  the producer's ``beginit`` makes the producer run once per consumption).
- :class:`MaxFrequency` forwards its messages no closer together than ``1/hz`` (the first at once):
  into an activity's ``beginit``, from its own ``endit``, a clock's or a consumer's, it bounds that
  activity's rate (FlowVR's MaxFrequencySynchronizor, Figure 1 c).
- :class:`Greedy` gives the reader, each time it asks, the newest message written, or nothing new
  (the reader then reuses the last one, ``OLD_DATA``): writer and reader run at their own rates
  (FlowVR's GreedySynchronizor + FilterIt pair, Figure 1 d).
- :class:`Merge` joins the connections into one input port: once each holds a message, the reader
  gets one tuple of their values, stamped as the first connection's message (FlowVR's FilterMerge).
- :class:`Split` shares the messages of one output among its connections that carry it, one
  connection each message, in turn or by a user stamp (FlowVR's split, a scatter).
- :class:`Cull` forwards a message only when its bounding box (a user stamp) meets the receiver's
  region, given to the filter (a box, or a view frustum): one Cull on each connection of an output
  routes each message to the receivers that see it (FlowVR Render's culling against each viewer's
  frustum).

- :class:`Gather` joins many connections into one input port as FlowVR's binary tree of merges
  does: the reader gets the nested pairs (``((a, b), (c, d))``), stamped as the first's message.

A ``Broadcast`` is what an output with several connections already does (each gets every message,
with its own policy or filter; ``docs/flowvr.md``).

Every filter keeps the counting contract of :class:`~coco_core.connections.Connection` (a token a
filter adds counts as written; a message it discards, as dropped), so the profile shows them.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from typing import Any, Callable, ClassVar

from .connections import EMPTY, CountedConnection
from .errors import PolicyError
from .frustum import Frustum
from .policy import ConnectionPolicy
from .stamps import Message


class Filter(CountedConnection):
    """A connection whose storage is a filter: by default a LOCKED BUFFER's bounded FIFO of
    messages, which the filters below change where they hold back, add, drop or pick messages.

    ``policy.size`` bounds the buffer (a message written to a full one is refused and counted as
    dropped, as a BUFFER connection's); writer and reader may be in any two threads. A filter reads
    the stamps of what it holds: a port's write comes to it as a :class:`Message`
    (:meth:`~coco_core.connections.Connection.put`), not as the record a policy's connection keeps."""

    __slots__ = ("_queue", "_size", "_lock")

    carries_stamps = True
    name: ClassVar[str] = ""
    """The filter's name in the XML's ``<filter type="...">``."""

    def __init__(self, policy: ConnectionPolicy) -> None:
        super().__init__(policy)
        self._queue: deque[Any] = deque()
        self._size = policy.size
        self._lock = threading.Lock()

    def push(self, value: Any) -> None:
        with self._lock:
            self.written += 1
            if len(self._queue) >= self._size:
                return
            self._queue.append(value)
        if self.trigger is not None:
            self.trigger()

    def pop(self) -> Any:
        with self._lock:
            if self._queue:
                self.read += 1
                return self._queue.popleft()
            return EMPTY

    @property
    def pending(self) -> int:
        return len(self._queue)

    def ready_at(self) -> float | None:
        return 0.0 if self._queue else None

    def _token(self, number: int) -> Message:
        """A message the filter itself adds: no payload, stamped by the filter."""
        return Message(None, time.perf_counter(), number, f"{self.name}({self.label})", -1)

    def settings(self) -> str:
        """The filter and its parameters (in place of a policy)."""
        return self.name

    def __repr__(self) -> str:
        return f"<{self.describe()} {self.label}>"


class PreSignal(Filter):
    """Starts with ``tokens`` messages, then forwards every message in order (FlowVR's
    FilterPreSignal): a cycle of activities needs a first message to start."""

    __slots__ = ("tokens",)
    name = "PreSignal"

    def __init__(self, policy: ConnectionPolicy, tokens: int = 1) -> None:
        if tokens < 0:
            raise PolicyError(f"PreSignal needs tokens >= 0, got {tokens}")
        if tokens > policy.size:
            raise PolicyError(f"PreSignal with {tokens} tokens needs a buffer of at least {tokens} messages "
                              f"(buffersize), got {policy.size}")
        super().__init__(policy)
        self.tokens = tokens
        for number in range(1, tokens + 1):
            self.written += 1
            self._queue.append(self._token(number))

    def settings(self) -> str:
        return f"PreSignal(tokens={self.tokens})"


class MaxFrequency(Filter):
    """Forwards its messages in order, the first at once and each later one no earlier than
    ``1/hz`` after the one before was taken (FlowVR's MaxFrequencySynchronizor: min(incoming rate,
    hz)). It starts with one token, so that an activity whose ``endit`` comes back to its own
    ``beginit`` through it starts."""

    __slots__ = ("hz", "_interval", "_taken_at")
    name = "MaxFrequency"

    def __init__(self, policy: ConnectionPolicy, hz: float) -> None:
        if not (math.isfinite(hz) and hz > 0):
            raise PolicyError(f"MaxFrequency needs hz > 0, got {hz}")
        super().__init__(policy)
        self.hz = hz
        self._interval = 1.0 / hz
        self._taken_at = -math.inf
        self.written += 1
        self._queue.append(self._token(1))

    def ready_at(self) -> float | None:
        if not self._queue:
            return None
        return max(0.0, self._taken_at + self._interval)

    def pop(self) -> Any:
        with self._lock:
            now = time.perf_counter()
            if not self._queue or now < self._taken_at + self._interval:
                return EMPTY
            self._taken_at = now
            self.read += 1
            return self._queue.popleft()

    def settings(self) -> str:
        return f"MaxFrequency(hz={self.hz:g})"


class Greedy(Filter):
    """The newest message written, once, to a reader that asks at its own rate: a write replaces
    the message not taken yet (counted as dropped), a read with nothing newer gets nothing (the
    input port then returns the last value again, ``OLD_DATA``: the reader is told to reuse it).

    FlowVR builds this pattern from a GreedySynchronizor (on each of the reader's ``endIt``, the
    stamp of the newest message) and a FilterIt (forward that message, discard the older): inside
    one process both are the one choice made at the reader's request, here."""

    __slots__ = ("reused", "_delivered")
    name = "Greedy"

    def __init__(self, policy: ConnectionPolicy) -> None:
        super().__init__(ConnectionPolicy(policy.data, policy.sync, 1))
        self.reused = 0
        """Reads that found nothing newer than the message the reader had (it reuses that one)."""
        self._delivered = False

    def push(self, value: Any) -> None:
        with self._lock:
            self.written += 1
            self._queue.clear()  # the one not taken is dropped (written - read - pending)
            self._queue.append(value)
        if self.trigger is not None:
            self.trigger()

    def pop(self) -> Any:
        with self._lock:
            if self._queue:
                self.read += 1
                self._delivered = True
                return self._queue.popleft()
            if self._delivered:
                self.reused += 1
            return EMPTY

    def pop_newest(self) -> Any:
        """The one message held is the newest: a second look would count a reuse."""
        return self.pop()


class MergeGroup:
    """The connections of one :class:`Merge`, in order: what the reader gets is one message from
    each, taken together when each has one."""

    def __init__(self) -> None:
        self.inputs: list[Merge] = []
        self.feeds: list[Callable[[], None]] = []
        """What moves the messages of the inputs fed from another process into their filters
        (:meth:`coco_core.processes.filtered.FedFilter.pull`): called before each look, in the
        reader's thread, so that a merge sees every input's messages wherever its writer runs."""

    def ready(self) -> bool:
        """Whether every input holds a message (only the reader takes them: this stays true)."""
        for feed in self.feeds:
            feed()
        return all(connection.pending for connection in self.inputs)

    def take(self) -> Any:
        """One message from each input, merged; :data:`EMPTY` unless each has one."""
        if not self.ready():
            return EMPTY
        items = [Filter.pop(connection) for connection in self.inputs]
        for connection, item in zip(self.inputs[1:], items[1:]):  # the reader's port times the first
            if connection.age is not None:
                connection.age.took(item)
        values = self.joined(tuple(item.value if type(item) is Message else item for item in items))
        first = items[0]
        if type(first) is Message:
            return Message(values, first.time, first.seq, first.source, first.it)
        return values

    def joined(self, values: tuple[Any, ...]) -> Any:
        """What the reader gets of one value from each input, in order: their tuple."""
        return values

    def skip(self) -> None:
        """Count the messages of a merged message the reader took and discarded as dropped."""
        for connection in self.inputs:
            connection.skip()


class Merge(Filter):
    """One input of a merge: the connections into one input port that each carry this filter form
    one :class:`MergeGroup` (in the order they were made, the file's). The reader's port reads the
    merged message through the first of them: the tuple of one value of each connection, stamped
    as the first's message (FlowVR's FilterMerge: in0's stamp, the data of in0, in1, ...); it waits
    until each connection holds a message, and each keeps its own FIFO (``buffersize``) meanwhile.
    FlowVR builds a binary tree of such filters for many inputs across hosts; in one process one
    merge takes any number."""

    __slots__ = ("group", "index")
    name = "Merge"

    def __init__(self, policy: ConnectionPolicy, group: MergeGroup) -> None:
        super().__init__(policy)
        self.group = group
        self.index = len(group.inputs)
        group.inputs.append(self)

    def pop(self) -> Any:
        return self.group.take() if self.index == 0 else EMPTY

    def pop_newest(self) -> Any:
        """The newest merged message; every older complete one counts as dropped on each input."""
        newest = self.pop()
        if newest is EMPTY:
            return EMPTY
        while (merged := self.pop()) is not EMPTY:
            self.group.skip()
            newest = merged
        return newest

    def ready_at(self) -> float | None:
        return 0.0 if self.index == 0 and self.group.ready() else None

    def settings(self) -> str:
        return f"Merge(in{self.index} of {len(self.group.inputs)})"


class GatherGroup(MergeGroup):
    """The connections of one :class:`Gather`: a :class:`MergeGroup` whose reader gets the values
    joined as FlowVR's binary tree of two-input merges would: neighbours in pairs, level by level,
    an odd one out carried up to the next level (``a, b, c, d, e`` gives ``(((a, b), (c, d)), e)``)."""

    def joined(self, values: tuple[Any, ...]) -> Any:
        level: list[Any] = list(values)
        while len(level) > 1:
            pairs: list[Any] = [(level[index], level[index + 1]) for index in range(0, len(level) - 1, 2)]
            level = pairs + level[len(pairs) * 2:]
        return level[0]


class Gather(Merge):
    """One input of a gather: FlowVR's binary tree of merges (``FilterMerge`` nodes) gathering many
    connections into one input port, as one filter: the connections into one port that each carry
    it form one :class:`GatherGroup` (file order gives each its leaf), and the reader gets, once
    every connection holds a message, the nested pairs of one value of each, stamped as the first
    connection's message (each node of FlowVR's tree is stamped as its in0's, so the root as the
    first leaf's). Inside one reader's process (where the filter runs, whichever processes or hosts
    its writers are in) a node needs no buffer or thread of its own: the tree is the shape of what
    is read, each connection keeping its own FIFO (``buffersize``) until its sibling's messages
    arrive."""

    __slots__ = ()
    name = "Gather"

    def __init__(self, policy: ConnectionPolicy, group: GatherGroup) -> None:
        super().__init__(policy, group)

    def settings(self) -> str:
        return f"Gather(leaf {self.index} of {len(self.group.inputs)})"


class Router(Filter):
    """A filter that routes: of the messages written on its connection, it keeps those for its
    reader and lets the others go to the other connections of the same output (FlowVR's routing
    filters). A message routed away was never this connection's: it is not counted as written here
    but as :attr:`routed_away`, which the profile shows in the policy column; a message that cannot
    be routed (its stamp missing or malformed) is counted as written and dropped."""

    __slots__ = ("routed_away",)

    def __init__(self, policy: ConnectionPolicy) -> None:
        super().__init__(policy)
        self.routed_away = 0
        """Messages this connection's reader was not to get (another connection's)."""

    def push(self, value: Any) -> None:
        keep = self.keeps(value)
        if keep is False:
            self.routed_away += 1
            return
        if keep is None:  # unroutable: offered here, and discarded (written - read - pending)
            self.written += 1
            return
        super().push(value)

    def keeps(self, item: Any) -> bool | None:
        """Whether ``item`` is for this connection's reader; None: it cannot be routed."""
        raise NotImplementedError

    def routes(self) -> str:
        """How it routes, for :meth:`settings`."""
        raise NotImplementedError

    def settings(self) -> str:
        return f"{self.routes()}, routed away {self.routed_away}"


def user_stamp(item: Any, name: str) -> Any:
    """The user stamp ``name`` of ``item`` (a :class:`Message`); None without one."""
    return item.user.get(name) if type(item) is Message else None


class Split(Router):
    """One output of a split: the connections from one output port that each carry this filter
    share its messages, each message going to one of them (FlowVR's split/scatter): in turn by the
    message's number (the ``index``-th of ``count`` takes messages ``index+1``, ``index+1+count``,
    ...), or, with ``by``, by the user stamp of that name (a whole number: it goes to connection
    ``stamp % count``). Each connection decides alone from the message's stamp, so a split needs
    no shared state and works with its connections' readers in any processes."""

    __slots__ = ("index", "count", "by")
    name = "Split"

    def __init__(self, policy: ConnectionPolicy, index: int, count: int, by: str = "") -> None:
        if not 0 <= index < count:
            raise PolicyError(f"Split output {index} of {count}: expected 0 <= index < count")
        super().__init__(policy)
        self.index = index
        self.count = count
        self.by = by

    def keeps(self, item: Any) -> bool | None:
        if self.by:
            key = user_stamp(item, self.by)
            if type(key) is not int:  # bool is no part number either
                return None
            return key % self.count == self.index
        if type(item) is not Message:
            return None
        return (item.seq - 1) % self.count == self.index

    def routes(self) -> str:
        how = f"by stamp {self.by}" if self.by else "in turn"
        return f"Split(out{self.index} of {self.count}, {how})"


class Cull(Router):
    """Forwards the messages whose bounding box (the user stamp ``stamp``, ``2k`` numbers: the
    minimum, then the maximum corner) meets the receiver's region, as FlowVR Render culls primitives
    against each viewer's frustum: one Cull per receiver, on each of the output's connections, each
    with its own region. The region is a box (``region``, ``2k`` numbers the same way: a tile of a
    display wall, a frustum's bounding box) or a true view ``frustum``
    (:class:`~coco_core.frustum.Frustum`, against 3-d boxes: a box is forwarded unless it is wholly
    outside one of the six planes). A message without the stamp is forwarded (it cannot be culled:
    every receiver gets it); one whose box has another dimension than the region's cannot be routed
    (dropped)."""

    __slots__ = ("stamp", "low", "high", "frustum")
    name = "Cull"

    def __init__(self, policy: ConnectionPolicy, region: tuple[float, ...] = (), stamp: str = "bbox",
                 frustum: Frustum | None = None) -> None:
        if frustum is not None:
            if region:
                raise PolicyError("Cull takes a region or a frustum, not both")
        elif not region or len(region) % 2 or not all(math.isfinite(value) for value in region):
            raise PolicyError(f"Cull needs a region of 2k finite numbers (minimum corner, then maximum), got {region}")
        half = len(region) // 2
        low, high = tuple(region[:half]), tuple(region[half:])
        if any(a > b for a, b in zip(low, high)):
            raise PolicyError(f"Cull region {region}: each minimum must be at most its maximum")
        super().__init__(policy)
        self.stamp = stamp
        self.low = low
        self.high = high
        self.frustum = frustum

    def keeps(self, item: Any) -> bool | None:
        box = user_stamp(item, self.stamp)
        if box is None:
            return True
        try:
            values = [float(value) for value in box]
        except (TypeError, ValueError):
            return None
        frustum = self.frustum
        if frustum is not None:
            return frustum.meets(values[:3], values[3:]) if len(values) == 6 else None
        half = len(self.low)
        if len(values) != 2 * half:
            return None
        return all(values[axis] <= self.high[axis] and self.low[axis] <= values[half + axis] for axis in range(half))

    def routes(self) -> str:
        if self.frustum is not None:
            return f"Cull({self.stamp} in {self.frustum.given})"
        return f"Cull({self.stamp} meets {' '.join(f'{v:g}' for v in self.low + self.high)})"


FILTERS: dict[str, type[Filter]] = {cls.name: cls for cls in (PreSignal, MaxFrequency, Greedy, Merge, Gather, Split,
                                                               Cull)}
"""Every filter by its XML name."""
