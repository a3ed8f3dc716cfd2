"""``process_level``: what both launchers wrap around a run of an application with ``<process>``."""


from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from typing import Any

from ..application import Application
from ..deployment import HostDeployment, drive
from ..levels import OtherHosts
from .supervisor import ProcessSupervisor


@contextlib.contextmanager
def process_level(app: Application, deployment: HostDeployment, log_level: int = logging.INFO,
                  hosts: OtherHosts | None = None, **options: Any) -> Iterator[ProcessSupervisor | None]:
    """Start the children of ``deployment`` (one host's plan) around a run of ``app`` (the launcher's part),
    whose thread drivers the launcher's own activities get here (:func:`coco_core.deployment.drive`);
    None when the application has no ``<process>``. Raises :class:`ProcessError` when a child cannot be built. At
    the end, children still running are given the stop time (:meth:`ProcessSupervisor.join`: a
    second after a hard stop, what their work needs after a natural one), then killed, and every
    resource of the launch is released. ``options`` go to :class:`ProcessSupervisor`.

    Here the levels meet, once (:mod:`coco_core.levels`): ``hosts`` (the other hosts, when the
    application has several) is given to the supervisor, and the application's router is set, the
    one place it is: the supervisor when there are child processes (it passes other hosts' calls
    on), else the other hosts."""
    if len(deployment.processes) == 1:
        drive(app, deployment, {})
        app.router = hosts
        yield None
        return
    supervisor = ProcessSupervisor(app, deployment, log_level, hosts=hosts, **options)
    supervisor.launch()
    app.router = supervisor
    try:
        yield supervisor
    finally:
        if not app.stop_requested:  # the launcher ends early (an error): the children too
            app.request_stop("launcher ends", hard=True)
        supervisor.join()
        supervisor.close()
