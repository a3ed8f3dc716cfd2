"""An activity's ``beginit`` and ``endit`` ports (FlowVR's): its cycles as messages in the data flow.

FlowVR chooses how two tasks at different rates are coupled in the network, not in their code: a
module waits for a message on its ``beginIt`` port before each iteration (when that port is
connected) and writes one on ``endIt`` after it. Connecting a consumer's ``endit`` to a producer's
``beginit`` (through a :class:`~coco_core.filters.PreSignal` that puts the first token in the cycle)
makes the producer run once per consumption; connecting an activity's ``endit`` back to its own
``beginit`` through a :class:`~coco_core.filters.MaxFrequency` bounds its rate; and so on
(``docs/flowvr.md``). Here the ports belong to the *activity*, the scheduling tree's unit that
iterates, and are ordinary ports: ``<src activity="name" port="endit"/>`` in the XML, any policy.

The activity calls :meth:`IterationPorts.begin` before a cycle and :meth:`IterationPorts.end`
after it, and nothing else: what waiting means is decided here. A triggered activity is woken by a
message on ``beginit`` (as by data on an event port) and waits in its own thread for a message that
may not be taken yet (a :class:`~coco_core.filters.MaxFrequency` releases its tokens on a time
grid); a periodic one skips the ticks at which no message may be taken.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from .component import Component
from .connections import EMPTY
from .ports import InputPort, OutputPort
from .stamps import Message, Stamp

if TYPE_CHECKING:
    from .activity import Activity

BEGIN = "beginit"
END = "endit"
PORTS = (BEGIN, END)
WAIT_SLICE = 0.02
"""Longest sleep, in seconds, of a triggered activity waiting for a begin message to be due: a stop
is seen within it."""


class IterationPorts(Component):
    """The ``beginit`` input and ``endit`` output of one activity, named after it (``produce.endit``).

    A component only in name: it holds the two ports (so that connections, their policies, the
    profile and the stamps treat them as any other), is not part of the application's components
    and is never updated; the activity calls :meth:`begin` and :meth:`end`."""

    beginit = InputPort(object, event=True, doc="when connected, each cycle of the activity waits for a "
                                                "message on every connection into it (FlowVR's beginIt)")
    endit = OutputPort(int, doc="one message after each cycle, the cycle's number (FlowVR's endIt)")

    def __init__(self, activity: Activity) -> None:
        super().__init__(activity.name)
        self.activity = activity
        self.beginit.set_wake(activity.wake)  # a message wakes a triggered activity (a periodic one ignores it)
        self.begun: Stamp | None = None
        """The stamp of the begin message that let the last cycle run (the first connection's)."""

    def begin(self) -> bool:
        """Whether the cycle may run: ``beginit`` is not connected, or a message could be taken from
        every connection into it (and was). A triggered activity sleeps here until a message that is
        there becomes due; a periodic one does not wait (the next tick looks again)."""
        connections = self.beginit.connections
        if not connections:
            return True
        due = 0.0
        for connection in connections:
            at = connection.ready_at()
            if at is None:
                return False
            due = max(due, at)
        activity = self.activity
        assert activity is not None
        if due > time.perf_counter() and not (activity.wakes_on_data and _sleep_until(activity, due)):
            return False
        items = [connection.pop() for connection in connections]
        for connection, item in zip(connections, items):
            if connection.age is not None:
                connection.age.took(item)
        first = items[0]
        self.begun = first.stamp if type(first) is Message else None
        return all(item is not EMPTY for item in items)

    def end(self) -> None:
        """After a cycle: write its number on ``endit`` (if connected)."""
        if self.endit.connections:
            activity = self.activity
            assert activity is not None
            self.endit.write(activity.stats.cycles)


def _sleep_until(activity: Activity, due: float) -> bool:
    """Sleep in the activity's thread until ``due``; False when a stop came first."""
    while (left := due - time.perf_counter()) > 0:
        if activity.stopping:
            return False
        time.sleep(min(left, WAIT_SLICE))
    return not activity.stopping


def iteration_ports(activity: Activity) -> IterationPorts:
    """The begin/end ports of ``activity``, made at the first call (when a connection names one)."""
    if activity.iteration is None:
        activity.iteration = IterationPorts(activity)
    return activity.iteration


def port_of(activity: Activity, name: str) -> InputPort | OutputPort:
    """``beginit`` or ``endit`` of ``activity``; another name is an error that lists the two."""
    from .errors import UnknownNameError

    ports = iteration_ports(activity)
    if name == BEGIN:
        return ports.beginit
    if name == END:
        return ports.endit
    raise UnknownNameError(f"activity {activity.name} has no port {name!r}; an activity's ports are "
                           f"{' and '.join(PORTS)}")
