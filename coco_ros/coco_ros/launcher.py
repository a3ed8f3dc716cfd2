"""``launcher`` of ``coco_ros``: run a CoCo application file inside one rclpy node.

    ros2 run coco_ros launcher app.xml [name:=value ...] [--host NAME [--host-timeout S]] [--duration S] [--profile S]
                               [--check [--allow-unknown] [--graph FILE]] [--list]
                               [--threads NAME[,NAME]] [--all-threads] [--executor-threads N] [--managed]
                               [--expose PATTERN]
                               [--ros-args -r __node:=NAME -p param:=value ...]

The command line is ``coco-launch``'s (same file format, same ``name:=value`` arguments, same
``--profile`` report); everything after ``--ros-args`` goes to ``rclpy.init``: remapping (the node's
name is the application's, ``-r __node:=NAME`` renames it), parameters (``-p``, declared on the node
from the overrides), log levels. Each of the application's activities runs in a wait set of its own
on a thread of its own (its timer or guard condition and its components' ROS entities:
:mod:`coco_ros.wait_set`), as callback groups of one rclpy executor (``--executor-threads N``), or
on the activity's own loop (:mod:`coco_ros.hosting` decides, ``--threads`` overrides). Ctrl-C (or
SIGTERM) stops every activity within a second, after each component's ``on_stop`` ran
(:mod:`coco_core.signals`: the rules and the exit statuses). With ``--host NAME`` it runs that host's
part of an application over several hosts (``docs/hosts.md``), its node named ``<application>_<host>``.

Components reach the node through ``coco_ros.hosting.ros_node(self)`` (``app.host.node``). What the
ROS tools see of the application: its ``<arg>``s and its components' attributes as parameters
(:mod:`.parameters`, :mod:`.component_parameters`), output ports mirrored on topics by the file's
``<topics>`` and ``--expose`` (:mod:`.mirror`), and ``ros_launcher:=true`` given to a file that
declares that arg (:data:`HOST_ARGS`).
"""

from __future__ import annotations

import argparse
import logging
import re
import sys
from functools import partial
from pathlib import Path
from typing import Sequence

from coco_core import Application, CocoError
from coco_core.errors import Interrupted
from coco_core.applications import find_application
from coco_core.model import AppSpec
from coco_core.deployment import HostDeployment, deployed
from coco_core.launcher import (
    HUNG,
    USAGE,
    begin,
    check,
    failure,
    launch,
    launcher_services,
    load_and_build,
    make_parser,
    parse_assignments,
)
from coco_core.processes.supervisor import ProcessSupervisor
from coco_core.report import snapshot
from coco_core.signals import INTERRUPTED, LaunchSignals, leave
from coco_core.xml import load_application
from rclpy.executors import Executor
from rclpy.node import Node

from .fastdds_segments import remove_abandoned
from .deployment import RosChildConfig, RosRules
from .hosting import ExecutorHost, ExecutorThread
from .managed import ManagedApplication, ManagedLauncherNode
from .mirror import PortMirrors, check_mirrors
from .diagnostics import ProfileDiagnostics
from .operation_services import OperationServices
from .component_parameters import ComponentParameters
from .parameters import ArgParameters, given_parameters
from .rosout import RosoutLogging

log = logging.getLogger("coco")

PROG = "ros2 run coco_ros launcher"
_NAME = "launcher"
"""How the launcher names itself in its error messages."""


HOST_ARGS = {"ros_launcher": "true"}
"""What the ROS launcher tells an application that declares these args (ranked as the node's
parameters: below ``name:=value``): a file keeps what only a node can do (a TFBridge, /robot_description)
to ``if="$(arg ros_launcher)"``, and ``coco-launch`` runs the rest of it untouched."""


def make_ros_parser() -> argparse.ArgumentParser:
    """``coco-launch``'s parser plus the hosting options of the ROS launcher."""
    parser = make_parser(prog=PROG)
    parser.description = ("Run a CoCo application file inside one rclpy node. ROS arguments follow "
                          "--ros-args (e.g. --ros-args -r __node:=my_name -p param:=value).")
    parser.add_argument("--threads", action="append", default=[], metavar="NAME[,NAME]",
                        help="run these activities on threads of their own instead of the executor")
    parser.add_argument("--all-threads", action="store_true",
                        help="run every activity on its own thread (as coco-launch does)")
    parser.add_argument("--managed", action="store_true",
                        help="a managed (lifecycle) node: the application configures on the configure transition and "
                             "runs on activate; deactivate holds it until the next activate; cleanup or shutdown stop "
                             "it (coco_ros.managed)")
    parser.add_argument("--expose", action="append", default=[], metavar="PATTERN",
                        help="mirror the output ports matching component.port (wildcards; all: every one) on "
                             "ROS topics ~/<component>/<port> (coco_ros.mirror)")
    parser.add_argument("--executor-threads", type=_positive_int, metavar="N",
                        help="host the activities as callback groups of one executor with N threads (1: a "
                        "SingleThreadedExecutor) instead of a wait set on a thread of its own for each")
    return parser


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a number of threads >= 1, got {text}")
    return value


def node_name(app_name: str) -> str:
    """A valid ROS node name made from an application name (letters, digits, underscores)."""
    name = re.sub(r"[^A-Za-z0-9_]", "_", app_name) or "coco"
    return f"coco_{name}" if name[0].isdigit() else name


def split_ros_args(argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """(the launcher's own words, the ``--ros-args ... [--]`` sections) of ``argv``.

    Split here rather than by rclpy's ``remove_ros_args``: rcl also takes every ``name:=value``
    outside those sections as a deprecated remap rule, which would swallow the application's
    ``<arg>`` values (``bag:=...``) and remap topics called ``bag``.
    """
    own: list[str] = []
    ros: list[str] = []
    inside = False
    for word in argv:
        if word == "--ros-args":
            inside = True
            ros.append(word)
        elif inside and word == "--":
            inside = False
        else:
            (ros if inside else own).append(word)
    return own, ros


def _threads(values: Sequence[str]) -> list[str]:
    return [name.strip() for value in values for name in value.split(",") if name.strip()]


def run(options: argparse.Namespace, ros_args: Sequence[str] = (), signals: LaunchSignals | None = None) -> int:
    """Load, build and run according to parsed ``options``; ``ros_args`` go to ``rclpy.init`` (the
    whole command line may be given: rcl only takes its ``--ros-args`` sections).

    Returns the exit code: 0 after a clean stop, 1 for a wrong file or a component that stopped the
    application, 2 for a wrong command line, 128 + the signal number when a signal came before the
    application ran or a second Ctrl-C during its stop (:mod:`coco_core.signals`), :data:`HUNG`
    when an activity did not stop in time.
    """
    early = begin(options, _NAME)
    if early is not None:
        return early
    signals = signals or LaunchSignals().install()  # before anything is read: a Ctrl-C at any moment counts
    if options.managed and options.executor_threads is not None:
        print(f"{_NAME}: --managed needs the default hosting (a wait set per activity): with --executor-threads the "
              "activities would configure in the executor that serves the configure transition", file=sys.stderr)
        return USAGE
    built = None
    if not sets_parameters(ros_args):
        # No -p / --params-file: the file is loaded and built before rclpy starts, so a wrong one is
        # reported before any node appears.
        if options.check:
            return check(options, signals, RosHost(), HOST_ARGS)
        try:
            built = load_and_build(options, signals, RosHost(), HOST_ARGS)
        except CocoError as error:
            return failure(_NAME, error)
    if options.host is not None:  # before the node: Fast DDS reads its profiles at the first participant
        from .hosts.fastdds import use_hosts_profile

        use_hosts_profile()
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    _remove_abandoned_segments("killed ROS processes (a launcher, a child)")
    try:
        rclpy.init(args=[_NAME, *ros_args], signal_handler_options=SignalHandlerOptions.NO)
    except Exception as error:  # a malformed --ros-args section
        print(f"{_NAME}: malformed --ros-args section: {error}", file=sys.stderr)
        return USAGE
    node = None
    try:
        # With -p / --params-file, the node comes first: its values are the file's args too.
        name = built[0].spec.name if built else application_name(options, signals)
        if options.host is not None:  # every host of one application has a launcher node: each its own name
            name = f"{name}_{options.host}"
        node_type = ManagedLauncherNode if options.managed else Node
        node = node_type(node_name(name), automatically_declare_parameters_from_overrides=True)
        given = given_parameters(node)
        if options.check:
            return check(options, signals, RosHost(), {**HOST_ARGS, **given})
        with RosoutLogging(node):  # CoCo's log lines on /rosout too, from here on
            host = RosHost(node, ros_args, options.expose)
            deployment, app = built or load_and_build(options, signals, host, {**HOST_ARGS, **given})
            ArgParameters(node, deployment.spec).declare(given)
            ComponentParameters(node, app).declare()
            signals.check()
            return launch(deployment, app, options, signals, host)
    except CocoError as error:  # a wrong file, interrupted while the children started, a child not built
        return failure(_NAME, error)
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        _remove_abandoned_segments("a child killed during the launch")


def _remove_abandoned_segments(left_by: str) -> None:
    """Remove the Fast DDS segment pairs that dead participants left (:mod:`.fastdds_segments`)."""
    removed = remove_abandoned()
    if removed:
        log.info("removed %d Fast DDS shared-memory segment(s) that %s left: %s", len(removed), left_by,
                 ", ".join(removed))


def sets_parameters(ros_args: Sequence[str]) -> bool:
    """Whether the ``--ros-args`` sections give the node parameters (``-p``, ``--param``,
    ``--params-file``), which may then give the application's args their values."""
    return any(word in ("-p", "--param", "--params-file") for word in ros_args)


class RosHost:
    """The ROS launcher's host (:class:`coco_core.launcher.LaunchHost`): the launcher's process's
    part in an rclpy node (a wait set per hosted activity, or the node's executor), the profile on
    /diagnostics, operations as services, optionally a managed (lifecycle) node; its children host
    their parts in nodes of their own (:mod:`.child`) by the same deployment plan."""

    prog = _NAME
    child_module = "coco_ros.child"

    def __init__(self, node: Node | None = None, ros_args: Sequence[str] = (), expose: Sequence[str] = ()) -> None:
        self.node = node
        """The launcher's node (None for ``--check``, which runs nothing)."""
        self.ros_args = list(ros_args)
        self.expose = list(expose)
        """``--expose`` patterns: the ports every process mirrors on topics (:mod:`.mirror`)."""

    def rules(self, options: argparse.Namespace) -> RosRules:
        return RosRules(tuple(_threads(options.threads)), options.all_threads,
                        wait_sets=options.executor_threads is None, executor_threads=options.executor_threads)

    def child_config(self) -> RosChildConfig:
        assert self.node is not None
        return RosChildConfig(self.node.get_name(), tuple(self.ros_args), tuple(self.expose))

    def checked(self, spec: AppSpec, app: Application, options: argparse.Namespace) -> list[str]:
        return check_mirrors(spec, app, options.expose, options.allow_unknown)

    def run(self, app: Application, deployment: HostDeployment, options: argparse.Namespace,
            processes: ProcessSupervisor | None, signals: LaunchSignals) -> bool:
        spec = deployment.spec
        node = self.node
        assert node is not None
        host, executor = host_in_node(node, app, deployment)
        if (options.executor_threads or 1) > 1:
            log.warning("--executor-threads %d: rclpy's MultiThreadedExecutor hosts the activities; it missed "
                        "wake-ups in docs/benchmarks.md (Figure 6: p99 2.4-566x a plain node, messages lost "
                        "from full DDS queues): prefer the default (a wait set per activity) or 1",
                        options.executor_threads)
        signals.attach(app)
        with (ProfileDiagnostics(node, app.name, processes.snapshots if processes else lambda: [snapshot(app)]),
              OperationServices(node, app, spec), PortMirrors(node, app, spec, self.expose)):
            managed = None
            if isinstance(node, ManagedLauncherNode):
                managed = node.managed = ManagedApplication(app, host)
            with launcher_services(app, options, processes):
                clean = run_hosted(app, host, executor, options.duration, managed)
        if clean:  # else a hung on_update keeps an executor worker busy: the entry point leaves at once
            host.close()
        return clean


def host_in_node(node: Node, app: Application, deployment: HostDeployment) -> tuple[ExecutorHost, Executor]:
    """Host this process's part of ``app`` in ``node`` by ``deployment`` (the launcher's process and
    every child's alike) and log where each activity runs; the host and the executor to spin."""
    host = ExecutorHost(node, app, deployment)
    executor = host.create_executor()
    executor.add_node(node)
    log.info("node %s hosts application %s", node.get_fully_qualified_name(), app.name)
    deployed(app, deployment)
    return host, executor


def application_name(options: argparse.Namespace, signals: LaunchSignals) -> str:
    """The name the launcher's node takes from the application (``<package name=...>``, else the
    file's stem), known before the node exists: the node's ``-p`` values may be needed to load the
    file in full, so a file that does not load yet is named by its stem (the load that follows says
    what is wrong)."""
    try:
        with signals.loading():
            return load_application(find_application(options.app), parse_assignments(options.args)).name
    except Interrupted:
        raise
    except CocoError:
        return Path(options.app).stem


def run_hosted(app: Application, host: ExecutorHost, executor: object, duration: float | None = None,
               managed: ManagedApplication | None = None) -> bool:
    """Start ``app``, spin ``executor`` in a thread of its own, run the main activity (if any) here,
    wait for a stop (or ``duration`` seconds), then stop cleanly while the executor still spins, so
    that hosted activities finish in their groups; whether the stop was clean. The launcher and its
    child processes (``coco_ros.child``) run their part of the application this way. ``managed``:
    the lifecycle's configure transition starts the application instead (:mod:`.managed`), and a
    stop before it stops nothing that ran."""
    spinner = ExecutorThread(executor, on_error=partial(app.request_stop, hard=True))  # type: ignore[arg-type]
    timer = None
    started = managed is None
    try:
        if managed is None:
            app.start()
            host.start()
        spinner.start()
        if managed is not None:
            started = managed.wait_started()
        if started:
            if duration is not None:
                timer = app.stop_after(duration)
            main = app.main_activity
            if main is not None:
                main.run_here()
        app.wait()
    finally:
        if timer is not None:
            timer.cancel()
        clean = app.stop() if started else True  # the executor still spins: hosted activities finish in their groups
        spinner.stop()  # then the node is destroyed and rclpy shut down
    return clean


def main(argv: Sequence[str] | None = None, signals: LaunchSignals | None = None) -> int:
    """Entry point (``lib/coco_ros/launcher``, through ``coco_core.entry``): ``argv`` without the
    program name; ``signals``: the launcher's signal handling when the entry point installed it."""
    argv = list(sys.argv[1:] if argv is None else argv)
    own, ros_args = split_ros_args(argv)
    options = make_ros_parser().parse_intermixed_args(own)
    code = run(options, ros_args, signals)  # only the --ros-args sections reach rcl
    if code in (HUNG, INTERRUPTED):  # a hung on_update, or a second Ctrl-C: do not wait for threads
        leave(1 if code == HUNG else code)
    return code


if __name__ == "__main__":
    sys.exit(main())
