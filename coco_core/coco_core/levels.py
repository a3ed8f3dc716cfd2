"""Where the host level and the process level meet: small protocols, wired once by the launch.

The scheduling tree's levels (:mod:`coco_core.deployment`: hosts > processes > activities) each run
their part of a launch: :mod:`coco_core.hosts` joins the other hosts (a session over a bus),
:mod:`coco_core.processes` starts this host's child processes (a supervisor). Each needs a little
of the other: the host level passes another host's calls and damage reports to the local processes
(:class:`LocalProcesses`: their routing and damage reporting), the process level passes its
children's calls to other hosts and their damage to the other hosts (:class:`OtherHosts`: the bus's
side of the session), and a child process that holds an end of a connection between hosts attaches
it (:class:`HostEnds`, which makes the :class:`Ends`). Neither level imports the other: what both
exchange lives beside them (:mod:`coco_core.messages`, :mod:`coco_core.calls`,
:mod:`coco_core.boundary`), and :func:`coco_core.launcher.launch` gives each the other's side
through these protocols (the session to :func:`~coco_core.processes.level.process_level`, the
supervisor to the session's ``built``, the host level's :class:`HostEnds` to every child's
configuration); ``process_level`` sets the application's router
(:attr:`Application.router <coco_core.application.Application.router>`) once, to the level that
routes every call. ``test/test_levels_apart.py`` reads both packages' imports, so that a shortcut
from one level into the other fails a test instead of growing back.
"""

from __future__ import annotations

from concurrent.futures import Future
from typing import TYPE_CHECKING, Any, Callable, Protocol

from .messages import Call, Outcome

if TYPE_CHECKING:
    from .application import Application
    from .model import AppSpec


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


class Ends(Protocol):
    """One process's ends of the connections between hosts (a transport's, over the network),
    closed at the process's end."""

    def unmatched(self) -> list[str]:
        """The ends whose other end on another host has not been found yet: a sample written before
        a writer found its reader would be lost, one written before a reader found its writer late,
        so no host starts before every end found its other."""

    def close(self) -> None: ...


class HostEnds(Protocol):
    """What a child process gets of the host level, in its configuration (so it travels to the
    child, pickled over the launch's pipe inside one host): how to attach the child's ends of the
    connections between hosts, on the application's clock and sealed with its key."""

    def attach(self, app: Application, spec: AppSpec) -> Ends | None:
        """Put ``app`` on the application's clock, attach the ends of ``spec``'s connections
        between hosts that ``app``'s process holds and wait until each found its other end (a
        :class:`~coco_core.errors.HostError` when one did not in time); None, and no network, when
        the process holds none."""
