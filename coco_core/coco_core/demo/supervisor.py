"""Reconfigures another component while it runs, through its operations."""

from __future__ import annotations

import logging
from concurrent.futures import Future

from ..attributes import Attribute
from ..component import Component

log = logging.getLogger("coco")


class Supervisor(Component):
    """Cycles ``target``'s ``operation`` through ``values``, one per activation.

    The call crosses activities: it is queued to the target's thread and its result comes back to
    this component's thread through ``send``'s callback, so neither side needs a lock.
    """

    target = Attribute(str, "", "instance name of the component to drive")
    operation_name = Attribute(str, "set_window", "operation of the target to call with each value")
    values = Attribute(list[int], [4, 16], "arguments, used in turn")

    def init(self) -> None:
        self.calls = 0
        self.replies: list[object] = []

    def on_config(self) -> None:
        self._operation = self.find_operation(self.target, self.operation_name)

    def on_update(self) -> None:
        value = self.values[self.calls % len(self.values)]
        self.calls += 1
        self._operation.send(value, callback=self._reply)

    def _reply(self, future: Future) -> None:
        result = future.result()
        self.replies.append(result)
        log.info("%s: %s.%s -> previous value %r", self.name, self.target, self.operation_name, result)
