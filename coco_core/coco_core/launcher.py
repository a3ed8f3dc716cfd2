"""``coco-launch``: run a CoCo application file without ROS.

    coco-launch app.xml [name:=value ...] [--host NAME [--host-timeout S]] [--duration S] [--profile S]
                [--check [--allow-unknown] [--graph FILE]] [--list]

Ctrl-C (or SIGTERM) stops every activity within a second, after each component's ``on_stop`` ran in
its own thread (:mod:`coco_core.signals` has the rules and the exit statuses). The ROS 2 launcher
(``coco_ros``) shares this command line.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import sys
import threading
from typing import Callable, Iterator, Mapping, Protocol, Sequence

from . import registry
from .applications import find_application
from .application import Application
from .builder import build_application, configure_logging
from .dataflow_graph import check_graph_file, write_graph
from .deployment import PLAIN, HostDeployment, LaunchRules, deployed, plan_deployment
from .errors import CocoError, CommandLineError, ConfigError, ConfigErrors, Interrupted
from .hosts.crossing import crossing_problems
from .hosts.key import launch_key
from .hosts.level import HostsLink, host_level
from .hosts.session import START_TIMEOUT
from .model import AppSpec
from .ports import InputPort
from .processes.level import process_level
from .processes.messages import HostConfig
from .processes.placement import LAUNCHER
from .processes.supervisor import ProcessSupervisor
from .report import profile_report
from .signals import INTERRUPTED, LaunchSignals, leave
from .xml import load_application

log = logging.getLogger("coco")


def parse_assignments(items: Sequence[str]) -> dict[str, str]:
    """``name:=value`` words of the command line (ROS 2 launch's syntax for arguments)."""
    args: dict[str, str] = {}
    for item in items:
        name, sep, value = item.partition(":=")
        if not sep or not name:
            raise CommandLineError(f"argument {item!r} must look like name:=value")
        args[name] = value
    return args


def make_parser(prog: str = "coco-launch") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description="Run a CoCo application file.")
    parser.add_argument("app", nargs="?",
                        help="application XML file, package:// URL, or the name of an installed application "
                             "(e.g. demo_pipeline: share/<package>/config/demo_pipeline.xml)")
    parser.add_argument("args", nargs="*", metavar="name:=value", help="values for the file's <arg>s")
    parser.add_argument("--duration", type=float, metavar="S",
                        help="stop S seconds after the application started running (every activity configured)")
    parser.add_argument("--profile", type=float, metavar="S",
                        help="print the profile (per component and activity timing) every S seconds and at exit")
    parser.add_argument("--check", action="store_true",
                        help="load and build the application, print its scheduling tree, do not run it")
    parser.add_argument("--allow-unknown", action="store_true",
                        help="with --check: report components that no installed package provides as "
                             "warnings, and check the rest of the structure")
    parser.add_argument("--graph", metavar="FILE",
                        help="with --check: write the data-flow graph (processes, activities, components, "
                             "connections with their policies, filters) as Graphviz DOT (FILE.dot or .gv), or "
                             "render it with Graphviz's dot (FILE.svg, .png or .pdf, with FILE.dot beside it)")
    parser.add_argument("--host", metavar="NAME",
                        help="the <host> of the application this machine is: run that host's part, joined to the "
                             "other hosts over DDS (each runs the same file with its own name)")
    parser.add_argument("--host-timeout", type=float, default=START_TIMEOUT, metavar="S",
                        help=f"with --host: seconds to wait for the other hosts at each stage of the start "
                             f"(default {START_TIMEOUT:g})")
    parser.add_argument("--key", metavar="FILE",
                        help="with --host: the application's key, which authenticates every message between its "
                             "hosts (coco-keygen FILE makes one; the same file on every host, mode 0600)")
    parser.add_argument("--key-env", metavar="NAME",
                        help="with --host: the environment variable that holds the application's key (64 "
                             "hexadecimal digits), instead of --key")
    parser.add_argument("--list", action="store_true", help="list the installed components and exit")
    parser.add_argument("--transforms-server", type=int, metavar="PORT",
                        help="serve the transformation graph (REST, WebSocket, web page) on 127.0.0.1:PORT "
                             "while the application runs (0: any free port)")
    parser.add_argument("--log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"])
    return parser


def list_components() -> str:
    """Installed components with their ports, attributes and operations."""
    lines = []
    for name, registration in sorted(registry.registrations().items()):
        try:
            cls = registry.load(name)
        except Exception as error:  # a broken third-party package must not hide the others
            lines.append(f"{name}  ({registration.target}): cannot be imported: {error}")
            continue
        lines.append(f"{name}  ({registration.target})")
        for decl in cls._attribute_decls.values():
            lines.append(f"    attribute {decl.name}: {decl.type_name} = {decl.default!r}  {decl.doc}".rstrip())
        for port in cls._port_decls.values():
            kind = "input" if isinstance(port, InputPort) else "output"
            lines.append(f"    {kind} {port.name}: {getattr(port.type, '__name__', port.type)}  {port.doc}".rstrip())
        if cls.dynamic_ports:
            lines.append(f"    ports {cls.dynamic_ports}")
        for op in cls._operation_decls:
            lines.append(f"    operation {op}")
    return "\n".join(lines)


def start_profile_printer(report: Callable[[], str], every: float) -> threading.Event:
    """Print ``report()`` every ``every`` seconds until the returned event is set."""
    done = threading.Event()

    def loop() -> None:
        while not done.wait(every):
            print(report(), flush=True)

    threading.Thread(target=loop, name="coco:profile", daemon=True).start()
    return done


@contextlib.contextmanager
def launcher_services(app: Application, options: argparse.Namespace,
                      processes: ProcessSupervisor | None = None) -> Iterator[None]:
    """What every launcher runs around an application: the profile (every
    ``--profile`` seconds and once at the end, of every process of the application) and the
    transformation graph's server (``--transforms-server``); the server stops and the final profile
    prints when the block ends."""
    report = processes.report if processes is not None else lambda: profile_report(app)
    printer = start_profile_printer(report, options.profile) if options.profile else None
    server = None
    if options.transforms_server is not None:
        from .transforms.server import TransformServer

        server = TransformServer(app.transforms, port=options.transforms_server).start()
        print(f"transformation graph served at {server.url}", flush=True)
    try:
        yield
    finally:
        if server is not None:
            server.stop()
        if printer is not None:
            printer.set()
            print(report(), flush=True)


USAGE = 2
"""The exit status for a wrong command line (the README's, argparse's)."""


def failure(prog: str, error: CocoError) -> int:
    """Say why a launch ended before or while it started, and the exit status for it: 128 + the
    signal number when a signal interrupted it, :data:`USAGE` when only the command line is wrong
    (:class:`CommandLineError`: a malformed ``name:=value``, an arg no file declares), else 1 (a
    wrong file, a child that could not start)."""
    print(f"{prog}: {error}", file=sys.stderr)
    if isinstance(error, Interrupted):
        return error.status
    errors = error.errors if isinstance(error, ConfigErrors) else [error]
    return USAGE if all(isinstance(each, CommandLineError) for each in errors) else 1


def stopped_by_a_failure(app: Application) -> bool:
    """Whether a component's error stopped the application (its ``on_error`` policy), damaged input
    was found (:attr:`Application.damage`, e.g. a truncated bag), a component refused input samples
    (the profile's ``refused`` column: a NaN joint value, a malformed message) or an activity failed
    (:attr:`Activity.failure`): the launcher then exits with 1, so that scripts notice. A child
    process decides its own status with this function, and a child's 1 fails the launch too."""
    if app.damage or any(activity.failure for activity in app.activities.values()):
        return True
    if any(component.stats.refused for component in app.components.values()):
        return True
    return any(c.stats.errors for c in app.components.values()) and app.stop_reason.startswith("component")


def load_spec(options: argparse.Namespace, signals: LaunchSignals,
              parameters: Mapping[str, str] | None = None) -> AppSpec:
    """The application file of ``options``, loaded whole (every host's part, when it declares hosts). A
    signal ends the reading of the file at once (:meth:`LaunchSignals.loading`). ``parameters``:
    values for the file's args ranked below the command line's ``name:=value`` (the ROS launcher's
    node parameters)."""
    if options.allow_unknown and not options.check:
        raise CommandLineError("--allow-unknown goes with --check only: an application without some of its "
                        "components cannot run")
    if options.graph is not None:
        if not options.check:
            raise CommandLineError("--graph goes with --check: it draws the application instead of running it")
        check_graph_file(options.graph)  # a wrong name fails before the file is read
    args = parse_assignments(options.args)
    log.debug("reading %s", options.app)
    with signals.loading():
        return load_application(find_application(options.app), args, parameters)


def log_warnings(spec: AppSpec) -> None:
    """What the file sets but this version ignores, and the components ``--allow-unknown`` left out
    (which building adds): logged once the application is built."""
    for warning in spec.warnings:
        log.warning("%s", warning)


def load_and_build(options: argparse.Namespace, signals: LaunchSignals, host: LaunchHost,
                   parameters: Mapping[str, str] | None = None) -> tuple[HostDeployment, Application]:
    """The application of ``options`` loaded (:func:`load_spec`), planned by ``host``'s rules (this
    host's part, with ``--host``) and the launcher's part built, its warnings logged; the building
    stops at its end on a signal."""
    spec = load_spec(options, signals, parameters)
    name = selected_host(spec, options, required=True)
    deployment = plan_deployment(spec, host.rules(options), name).host(name)
    app = build_application(deployment.spec, allow_unknown=options.allow_unknown, placement=deployment.placement)
    log_warnings(deployment.spec)
    return deployment, app


def selected_host(spec: AppSpec, options: argparse.Namespace, required: bool) -> str | None:
    """The ``<host>`` that ``--host`` names, None for an application that declares no host (or,
    unless ``required``, for every host of one that does: ``--check``); a
    :class:`CommandLineError` for ``--host`` (or a key) without hosts, and for none when required."""
    if not spec.hosts:
        if options.host is not None:
            raise CommandLineError(f"--host {options.host}: application {spec.name} declares no <host>; it runs on one "
                            "machine (docs/hosts.md)")
        if options.key is not None or options.key_env is not None:
            raise CommandLineError(f"--key and --key-env authenticate the hosts of an application; {spec.name} "
                                   "declares no <host>")
        return None
    if options.host is None and required:
        raise CommandLineError(f"application {spec.name} runs on several hosts ({', '.join(h.name for h in spec.hosts)}): "
                        "say which one this machine is with --host NAME")
    return str(options.host) if options.host is not None else None


HUNG = 3
"""What :func:`launch` returns when an activity did not stop within a second (its thread is
abandoned): the entry point then exits with 1 at once instead of waiting for that thread."""


class LaunchHost(Protocol):
    """What a launcher plugs in to run its process's part of an application: plain threads
    (:class:`PlainHost`, ``coco-launch``) or an rclpy node (``coco_ros.launcher.RosHost``). The
    rest of a launch (the deployment plan, the child processes, the profile, the exit status) is
    :func:`launch`'s, the same for every host."""

    prog: str
    """How the launcher names itself in its messages."""
    child_module: str
    """The module a child process runs (``python -m``): it hosts its part as this host does."""

    def rules(self, options: argparse.Namespace) -> LaunchRules:
        """The host's rules for the deployment plan, with what of the command line decides where
        activities run (:class:`~coco_core.deployment.LaunchRules`)."""

    def child_config(self) -> HostConfig:
        """What every child's host needs beyond the plan (:attr:`~.processes.messages.Config.host`)."""

    def checked(self, spec: AppSpec, app: Application, options: argparse.Namespace) -> list[str]:
        """``--check``: what the host adds to a built part of the application (lines to print), or a
        :class:`CocoError` naming what it cannot host (the ROS launcher: a port no topic can mirror)."""

    def run(self, app: Application, deployment: HostDeployment, options: argparse.Namespace,
            processes: ProcessSupervisor | None, signals: LaunchSignals) -> bool:
        """Host and run the launcher's part until a stop; whether the stop was clean."""


class PlainHost:
    """``coco-launch``: every activity on CoCo's own threads (:class:`LaunchHost`)."""

    prog = "coco-launch"
    child_module = "coco_core.processes.child"

    def rules(self, options: argparse.Namespace) -> LaunchRules:
        return PLAIN

    def child_config(self) -> HostConfig:
        return HostConfig()

    def checked(self, spec: AppSpec, app: Application, options: argparse.Namespace) -> list[str]:
        return [f"<topics>: {len(spec.topics)} port mirror(s) left to the ROS launcher"] if spec.topics else []

    def run(self, app: Application, deployment: HostDeployment, options: argparse.Namespace,
            processes: ProcessSupervisor | None, signals: LaunchSignals) -> bool:
        deployed(app, deployment)
        signals.attach(app)
        with launcher_services(app, options, processes):
            app.run(options.duration)
        return app.stop()


def begin(options: argparse.Namespace, prog: str) -> int | None:
    """What every launcher does first: logging, ``--list``, a missing file; an exit code when that
    ends the launch, else None."""
    logging.basicConfig(level=options.log_level, format="[%(levelname)s] %(name)s: %(message)s")
    if options.list:
        print(list_components())
        return 0
    if options.app is None:
        print(f"{prog}: an application file is needed (or --list)", file=sys.stderr)
        return USAGE
    return None


def check(options: argparse.Namespace, signals: LaunchSignals, host: LaunchHost,
          parameters: Mapping[str, str] | None = None) -> int:
    """``--check``: load, plan by ``host``'s rules and build every process's part (``parameters``:
    values for the file's args below the command line's, the ROS launcher's node parameters), print
    the plan (:meth:`~coco_core.deployment.Deployment.render`), run nothing. An application over
    several hosts is planned and printed host by host (the one ``--host`` names, or all)."""
    try:
        spec = load_spec(options, signals, parameters)
        deployment = plan_deployment(spec, host.rules(options), selected_host(spec, options, required=False))
        parts: dict[str, dict[str, Application]] = {}
        notes: dict[str, list[str]] = {}
        for name, planned in deployment.hosts.items():
            parts[name] = built = build_parts(planned, options.allow_unknown)
            crossing = crossing_problems(planned.spec) if not options.allow_unknown else []
            if crossing:
                raise ConfigErrors([ConfigError(problem) for problem in crossing])
            notes[name] = host.checked(planned.spec, built[LAUNCHER], options)
        log_warnings(spec)  # the parts share the file's list of warnings
        signals.check()
        print(deployment.render(parts, notes))
        if options.graph is not None:
            print(f"data-flow graph written to {', '.join(write_graph(deployment, options.graph))}")
    except CocoError as error:
        return failure(host.prog, error)
    return 0


def build_parts(deployment: HostDeployment, allow_unknown: bool) -> dict[str, Application]:
    """Every process's part of one host (``init`` only, nothing runs), so that ``--check`` reports a
    wrong component in any process: a :class:`ConfigErrors` with all of them."""
    parts = {LAUNCHER: build_application(deployment.spec, allow_unknown=allow_unknown,
                                         placement=deployment.placement)}
    errors: list[ConfigError] = []
    for name in deployment.processes:
        if name != LAUNCHER:
            try:
                parts[name] = build_application(deployment.spec, name, allow_unknown, deployment.placement)
            except ConfigErrors as error:
                errors += error.errors
    if errors:
        raise ConfigErrors(errors)
    return parts


def launch(deployment: HostDeployment, app: Application, options: argparse.Namespace, signals: LaunchSignals,
           host: LaunchHost) -> int:
    """Run a built application with ``host`` by ``deployment`` (this host's part of the plan): join
    the other hosts when it is one host's part (:mod:`coco_core.hosts`), start its child processes,
    let the host run the launcher's part to its stop; the exit code: 0 after a clean stop, 1 when a
    component stopped the application, damage was found, a child died or another host failed,
    :data:`HUNG` when an activity did not stop in time, 128 + the signal number after a second
    Ctrl-C (:mod:`coco_core.signals`)."""
    spec = deployment.spec
    app.measure_ages = bool(options.profile)  # the profile's age column, in every process
    level = logging.getLevelName(options.log_level)
    configure_logging(spec.log, level)  # may open the file's log
    key = launch_key(options) if spec.part_of else None
    if spec.part_of and key is None:
        raise CommandLineError(f"application {spec.name} runs on several hosts, which authenticate each other with "
                               "the application's key: give --key FILE or --key-env NAME (coco-keygen FILE makes one; "
                               "copy it to every host)")
    with host_level(spec, app, options.host_timeout, key, signals.check) as hosts:
        link = HostsLink(hosts.clock, key, options.host_timeout) if hosts is not None and key is not None else None
        with process_level(app, deployment, level, child_module=host.child_module,
                           child_config=host.child_config(), hosts_link=link, hosts=hosts) as processes:
            if hosts is not None:
                hosts.built(processes)
            clean = host.run(app, deployment, options, processes, signals)
    if signals.forced:
        return INTERRUPTED
    if not clean:
        return HUNG
    failed = (processes is not None and processes.failed) or (hosts is not None and bool(hosts.failure))
    return 1 if stopped_by_a_failure(app) or failed else 0


def run(options: argparse.Namespace, signals: LaunchSignals | None = None) -> int:
    """Load, build and run according to parsed ``options``; returns the exit code. ``signals``: the
    launcher's signal handling when the entry point installed it already."""
    host = PlainHost()
    early = begin(options, host.prog)
    if early is not None:
        return early
    signals = signals or LaunchSignals().install()  # before anything is read: a Ctrl-C at any moment counts
    if options.check:
        return check(options, signals, host)
    try:
        deployment, app = load_and_build(options, signals, host)
        signals.check()
        code = launch(deployment, app, options, signals, host)
    except CocoError as error:  # a wrong file, interrupted while the children started, a child not built
        return failure(host.prog, error)
    if code in (HUNG, INTERRUPTED):  # an activity that did not stop, or a second Ctrl-C: leave now
        leave(1 if code == HUNG else code)
    return code


def main(argv: Sequence[str] | None = None, signals: LaunchSignals | None = None) -> int:
    # Intermixed: `app.xml --duration 3 window:=4` puts an argument after an option.
    return run(make_parser().parse_intermixed_args(argv), signals)


if __name__ == "__main__":
    sys.exit(main())
