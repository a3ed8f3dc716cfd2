"""Relay: the values of one connection passed on to another by the relay's own activity.

Why: a value that reaches an activity from another process is copied out of shared memory and
unpickled by the thread that reads it. For a large value that is the thread's time: a 2.8 MB
search structure takes about a millisecond, a missed deadline for a 1 kHz haptic loop each time one
arrives. A Relay in a triggered activity of the loop's process reads the value on its own thread
and writes it on to the loop's component in-process, where a write hands over a reference: the loop
only finds a new value between two of its cycles, at no cost. The same holds for any slow path into
a real-time activity: give the slow part its own activity, and the hand-over is free.

Every value read is written on, in order (read_all): a DATA input passes the newest, a BUFFER input
every one; what the connections drop is counted on them, as everywhere.
"""

from __future__ import annotations

from .component import Component
from .ports import InputPort, OutputPort


class Relay(Component):
    """Passes every value of ``input`` on to ``output``, in its own activity."""

    input = InputPort(object, event=True, doc="values to pass on; each arrival wakes the relay's activity")
    output = OutputPort(object, "the same values, written in the relay's activity and process")

    def on_update(self) -> None:
        for value in self.input.read_all():
            self.output.write(value)
