"""``host_level``: what both launchers wrap around a run of one host's part of an application, and
:class:`HostsLink`, what its child processes get of it."""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from ..application import Application
from ..errors import ConfigError, ConfigErrors, KeyFileError
from ..levels import Ends
from ..model import AppSpec
from .clock import ClockOffset
from .crossing import crossing_problems
from .key import AppKey
from .session import HostSession, matched
from .transport import host_transport

log = logging.getLogger("coco")


@contextlib.contextmanager
def host_level(spec: AppSpec, app: Application, timeout: float, key: AppKey | None,
               interrupted: Callable[[], None] = lambda: None) -> Iterator[HostSession | None]:
    """Join the other hosts of ``spec`` (one host's part) around a run of ``app``: wait for them and
    measure the clock (:meth:`HostSession.join`), attach the launcher's process's ends of the
    connections between hosts; None when the application has one host. ``interrupted`` raises when
    a signal ends the launch while it waits. At the end, the other hosts are told that this one
    stops and the network is released. ``key`` (needed when it has several) authenticates every
    message between the hosts (:mod:`.auth`)."""
    if not spec.part_of:
        yield None
        return
    if key is None:
        raise KeyFileError(f"host {spec.part_of}: the hosts of application {spec.name} need its key")
    crossing = crossing_problems(spec)
    if crossing:
        raise ConfigErrors([ConfigError(problem) for problem in crossing])
    log.info("host %s: the application's key is %s (fingerprint %s: the same on every host)", spec.part_of,
             key.origin, key.fingerprint)
    transport = host_transport()
    session = HostSession(spec, app, timeout, interrupted)
    ends = None
    try:
        session.join(transport.bus(spec, session.receive, key, app.network_refusals))
        app.clock = session.clock
        ends = session.ends = ends_between_hosts(app, spec, session.clock, key)
        yield session
    finally:
        if not app.stop_requested:  # the launcher ends early (an error): the other hosts too
            app.request_stop(f"host {spec.part_of} ends", hard=True)
        if ends is not None:
            ends.close()
        session.close()


def ends_between_hosts(app: Application, spec: AppSpec, clock: ClockOffset, key: AppKey) -> Ends | None:
    """Attach the ends of ``spec``'s connections between hosts that this process of ``app`` holds
    (the launcher's process, or a child's); None, and no network, when it holds none."""
    here = [channel for channel in spec.between_hosts
            if (channel.src_host, channel.src_process) == (spec.part_of, app.process)
            or (channel.dest_host, channel.dest_process) == (spec.part_of, app.process)]
    return host_transport().attach(app, spec, clock, key) if here else None


@dataclass(frozen=True)
class HostsLink:
    """What a child process of one host of an application over several needs of the other hosts
    (:class:`~coco_core.levels.HostEnds`): the launch puts it in every child's configuration, so the
    process level carries it without knowing what it is."""

    clock: ClockOffset
    """This host's clock against the application's: a child with ends of connections between hosts
    puts its stamps on the application's clock."""
    key: AppKey
    """The application's key (:mod:`coco_core.hosts.key`): the child's ends of connections between
    hosts seal and check their samples with it (the launch's pipe is inside one host: one trust
    domain)."""
    timeout: float
    """Seconds a child waits for the other ends of its connections to other hosts (``--host-timeout``)."""

    def attach(self, app: Application, spec: AppSpec) -> Ends | None:
        app.clock = self.clock
        ends = ends_between_hosts(app, spec, self.clock, self.key)
        if ends is not None:
            try:
                matched(ends, self.timeout, lambda: None, app)
            except BaseException:  # the child fails to build: its network goes with it
                ends.close()
                raise
        return ends
