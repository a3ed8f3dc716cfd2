"""What a rendered frame shows first: the origins of the inputs that reach the screen in it.

Sensor-to-display latency (the paper's 89 ms for teleoperation) runs from the moment an input was
acquired or emitted upstream (its :class:`~coco_core.stamps.Stamp`) to the frame that first shows
it. Every display peer that takes an input keeps a :class:`ShownInputs`, ``shown``: the origin of a
value read from a port (``add`` of the port's :attr:`~coco_core.ports.InputPort.origin`: a
``Stamped`` value's own stamp, else the stamp of the message that carried it, so that a plain value
written through a port, in this process or another, is timed from its write), or a pose the peer
looked up in the transformation graph (``add_graph``:
the ``cause`` the graph's writer left on each edge or robot on the path, e.g. the joint state a
``TransformationInterface`` applied). GLManager ``take``\\ s them from all its peers once the frame is
drawn and stamps the frame with the oldest: the frame's own stamp, carried in the data it writes
(``Stamped`` image, ``latency`` port), never in thread-local state, so the stamps survive the
display moving to another process.

An input counts once, in the first frame that shows it: a frame that only repeats what earlier
frames showed has no input origin (nothing new reached the screen), rather than an ever-growing age.
"""

from __future__ import annotations

from typing import Iterable

from coco_core.stamps import Stamp


class ShownInputs:
    """The oldest origin among the inputs a peer took for the next frame; see the module docstring."""

    __slots__ = ("oldest", "_seen")

    def __init__(self) -> None:
        self.oldest: Stamp | None = None
        self._seen: dict[int, Stamp] = {}
        """Per graph dependency (edge or robot model, by id): the origin already reported."""

    def add(self, origin: Stamp | None) -> None:
        """An input with this origin (None: a value that came without a port's stamp, nothing to
        measure) is drawn in the next frame."""
        if origin is not None and (self.oldest is None or origin.time < self.oldest.time):
            self.oldest = origin

    def add_graph(self, dependencies: Iterable[object]) -> None:
        """A pose looked up through these graph dependencies is drawn: each one's origin counts once."""
        for dependency in dependencies:
            origin = getattr(dependency, "cause", None)
            if origin is not None and self._seen.get(id(dependency)) is not origin:
                self._seen[id(dependency)] = origin
                self.add(origin)

    def take(self) -> Stamp | None:
        """The oldest origin added since the last ``take`` (None when nothing stamped), and forget it."""
        oldest, self.oldest = self.oldest, None
        return oldest
