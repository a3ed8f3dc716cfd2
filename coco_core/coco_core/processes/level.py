"""``process_level``: what both launchers wrap around a run of an application with ``<process>``."""


from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from typing import Any

from ..application import Application
from ..deployment import HostDeployment, drive
from .supervisor import ProcessSupervisor


@contextlib.contextmanager
def process_level(app: Application, deployment: HostDeployment, log_level: int = logging.INFO,
                  **options: Any) -> Iterator[ProcessSupervisor | None]:
    """Start the children of ``deployment`` (one host's plan) around a run of ``app`` (the launcher's part),
    whose thread drivers the launcher's own activities get here (:func:`coco_core.deployment.drive`);
    None when the application has no ``<process>``. Raises :class:`ProcessError` when a child cannot be built. At
    the end, children still running are given the stop time (:meth:`ProcessSupervisor.join`: a
    second after a hard stop, what their work needs after a natural one), then killed, and every
    resource of the launch is released. ``options`` go to :class:`ProcessSupervisor`."""
    if len(deployment.processes) == 1:
        drive(app, deployment, {})
        yield None
        return
    supervisor = ProcessSupervisor(app, deployment, log_level, **options)
    supervisor.launch()
    try:
        yield supervisor
    finally:
        if not app.stop_requested:  # the launcher ends early (an error): the children too
            app.request_stop("launcher ends", hard=True)
        supervisor.join()
        supervisor.close()
