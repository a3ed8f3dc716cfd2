"""Output ports mirrored on ROS topics: ``<topics>`` in the application file, ``--expose PATTERN`` on the
ROS launcher's command line (:mod:`.plan`), published through :mod:`coco_ros.convert` by a connection
of the port (:mod:`.publisher`) that costs nothing while no one subscribes."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from coco_core import Application
from coco_core.model import AppSpec

from .plan import ALL, MirrorPlan, Mirrored, check_mirrors, plan_mirrors
from .publisher import TYPE_POLL_S, PortMirror


class PortMirrors:
    """The mirrors of one process's part of the application while it runs (a context manager):
    made before the application starts, closed after it stopped."""

    def __init__(self, node: Any, app: Application, spec: AppSpec, patterns: Sequence[str] = ()) -> None:
        from rclpy.callback_groups import MutuallyExclusiveCallbackGroup

        self.node = node
        group = MutuallyExclusiveCallbackGroup()
        plan = plan_mirrors(spec, app, patterns)
        self.mirrors = [PortMirror(node, group, app, mirrored) for mirrored in plan.mirrored]
        self._waiting: list[PortMirror] = []
        self._timer: Any = None
        self._group = group

    def __enter__(self) -> PortMirrors:
        self._waiting = [mirror for mirror in self.mirrors if not mirror.resolve()]
        if self._waiting:
            self._timer = self.node.create_timer(TYPE_POLL_S, self._resolve_waiting, callback_group=self._group)
        return self

    def _resolve_waiting(self) -> None:
        self._waiting = [mirror for mirror in self._waiting if not mirror.resolve()]
        if not self._waiting and self._timer is not None:
            self._timer.cancel()

    def __exit__(self, *exc: object) -> None:
        if self._timer is not None:
            self.node.destroy_timer(self._timer)
            self._timer = None
        for mirror in self.mirrors:
            mirror.close()


__all__ = ["ALL", "MirrorPlan", "Mirrored", "PortMirror", "PortMirrors", "check_mirrors", "plan_mirrors"]
