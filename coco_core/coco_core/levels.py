"""Where the host level and the process level meet: two small protocols, wired once by the launch.

The scheduling tree's levels (:mod:`coco_core.deployment`: hosts > processes > activities) each run
their part of a launch: :mod:`coco_core.hosts` joins the other hosts (a session over a bus),
:mod:`coco_core.processes` starts this host's child processes (a supervisor). Each needs a little
of the other: the host level passes another host's calls and damage reports to the local processes,
and the process level passes its children's calls to other hosts and their damage to the other
hosts. Neither names the other's class: :func:`coco_core.launcher.launch` gives each the other's
side through these protocols (the session to :func:`~coco_core.processes.level.process_level`, the
supervisor to the session's ``built``), and ``process_level`` sets the application's router
(:attr:`Application.router <coco_core.application.Application.router>`) once, to the level that
routes every call.
"""

from __future__ import annotations

from concurrent.futures import Future
from typing import Any, Callable, Protocol

from .processes.messages import Call, Outcome


class LocalProcesses(Protocol):
    """What the host level reaches of this host's processes (the process level's supervisor)."""

    def route(self, call: Call, reply: Callable[[Outcome], None]) -> None:
        """Run ``call`` in the process of this host that runs its component; ``reply`` gets the
        outcome as it came."""

    def pass_on_damage(self, what: str) -> None:
        """Damaged input that another host found: every process of this host reports it too."""


class OtherHosts(Protocol):
    """What the process level reaches of the other hosts (the host level's session)."""

    def call(self, process: str, component: str, operation: str, args: tuple[Any, ...],
             kwargs: dict[str, Any]) -> Future[Any]:
        """An operation of a component of another host (``process`` is its address, ``view@graphics``)."""

    def forward(self, call: Call, reply: Callable[[Outcome], None]) -> None:
        """Pass a child's ``call`` to the host of its address; ``reply`` gets the outcome as it came."""

    def damage_found(self, what: str) -> None:
        """Damaged input found on this host (a child process): every other host reports it too."""
