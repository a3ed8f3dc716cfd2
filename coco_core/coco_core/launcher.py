"""``coco-launch``: run a CoCo application file without ROS.

    coco-launch app.xml [name:=value ...] [--duration S] [--profile S] [--check] [--list]

Ctrl-C (or SIGTERM) stops every activity within a second, after each component's ``on_stop`` ran in
its own thread; a second Ctrl-C forces the exit. The ROS 2 launcher (``coco_ros``) shares this
command line.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import signal
import sys
import threading
from pathlib import Path
from typing import Iterator, Sequence

from . import registry
from .application import Application
from .builder import build_application, configure_logging
from .errors import CocoError
from .ports import InputPort
from .report import profile_report
from .xml import load_application

log = logging.getLogger("coco")


def parse_assignments(items: Sequence[str]) -> dict[str, str]:
    """``name:=value`` words of the command line (ROS 2 launch's syntax for arguments)."""
    args: dict[str, str] = {}
    for item in items:
        name, sep, value = item.partition(":=")
        if not sep or not name:
            raise CocoError(f"argument {item!r} must look like name:=value")
        args[name] = value
    return args


def make_parser(prog: str = "coco-launch") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=prog, description="Run a CoCo application file.")
    parser.add_argument("app", nargs="?", type=Path, help="application XML file")
    parser.add_argument("args", nargs="*", metavar="name:=value", help="values for the file's <arg>s")
    parser.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    parser.add_argument("--profile", type=float, metavar="S",
                        help="print the profile (per component and activity timing) every S seconds and at exit")
    parser.add_argument("--check", action="store_true",
                        help="load and build the application, print its scheduling tree, do not run it")
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
        for op in cls._operation_decls:
            lines.append(f"    operation {op}")
    return "\n".join(lines)


def describe(app: Application) -> str:
    """The scheduling tree and the connections, for ``--check``."""
    lines = [f"application {app.name}"]
    for activity, components in app.schedule_tree():
        lines.append(f"  activity {activity.name}: {activity.describe()}" if activity else "  (no activity)")
        for top in components:
            for component in top.walk():
                depth = 0
                owner = component.owner
                while owner is not None:
                    depth, owner = depth + 1, owner.owner
                lines.append(f"    {'  ' * depth}{component.name} ({type(component).__name__})")
    for connection in app.connections:
        lines.append(f"  {connection.source.qualified_name} -> {connection.sink.qualified_name}  {connection.policy}")  # type: ignore[union-attr]
    return "\n".join(lines)


def install_signal_handlers(app: Application) -> None:
    """First Ctrl-C / SIGTERM: clean stop. Second Ctrl-C: give up at once."""

    def handle(signum: int, _frame: object) -> None:
        if app.stop_requested and signum == signal.SIGINT:
            signal.signal(signal.SIGINT, signal.SIG_DFL)
            raise KeyboardInterrupt
        app.request_stop(f"received {signal.Signals(signum).name}")

    signal.signal(signal.SIGINT, handle)
    signal.signal(signal.SIGTERM, handle)


def start_profile_printer(app: Application, every: float) -> threading.Event:
    """Print the profile every ``every`` seconds until the returned event is set."""
    done = threading.Event()

    def loop() -> None:
        while not done.wait(every):
            print(profile_report(app), flush=True)

    threading.Thread(target=loop, name="coco:profile", daemon=True).start()
    return done


@contextlib.contextmanager
def launcher_services(app: Application, options: argparse.Namespace) -> Iterator[None]:
    """What every launcher runs around an application: Ctrl-C handling, the profile (every
    ``--profile`` seconds and once at the end) and the transformation graph's server
    (``--transforms-server``); the server stops and the final profile prints when the block ends."""
    install_signal_handlers(app)
    printer = start_profile_printer(app, options.profile) if options.profile else None
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
            print(profile_report(app), flush=True)


def stopped_by_a_failure(app: Application) -> bool:
    """Whether a component's error stopped the application (its ``on_error`` policy), or damaged
    input was found (:attr:`Application.damage`, e.g. a truncated bag): the launcher then exits with
    1, so that scripts notice."""
    if app.damage:
        return True
    return any(c.stats.errors for c in app.components.values()) and app.stop_reason.startswith("component")


def run(options: argparse.Namespace) -> int:
    """Load, build and run according to parsed ``options``; returns the exit code."""
    logging.basicConfig(level=options.log_level, format="[%(levelname)s] %(name)s: %(message)s")
    if options.list:
        print(list_components())
        return 0
    if options.app is None:
        print("coco-launch: an application file is needed (or --list)", file=sys.stderr)
        return 2
    try:
        spec = load_application(options.app, parse_assignments(options.args))
        app = build_application(spec)
    except CocoError as error:
        print(f"coco-launch: {error}", file=sys.stderr)
        return 1
    if options.check:
        print(describe(app))
        return 0
    configure_logging(spec.log, logging.getLevelName(options.log_level))  # may open the file's log
    with launcher_services(app, options):
        app.run(options.duration)
    clean = app.stop()
    return 0 if clean and not stopped_by_a_failure(app) else 1


def main(argv: Sequence[str] | None = None) -> int:
    # Intermixed: `app.xml --duration 3 window:=4` puts an argument after an option.
    return run(make_parser().parse_intermixed_args(argv))


if __name__ == "__main__":
    sys.exit(main())
