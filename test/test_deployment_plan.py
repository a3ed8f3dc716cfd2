"""One deployment plan: what ``--check`` prints is what every process of the run executes.

Two levels. In-process, for every application file of the workspace (``config/``, the test
applications, the original CoCo samples) and both hosts (plain, ROS): each process's part is built
as its process builds it, given the drivers the launchers give it (the process level's eventfds from
the real channel plan, the ROS host's wait sets on a real node), and checked against the plan
(``coco_core.deployment.verify``), and ``--check``'s tree shows the plan's line for every activity.
End to end, on applications with child processes: both launchers' ``--check`` lines equal the lines
each process logs when it runs (with ``--executor-threads`` and ``--threads`` too).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest
import rclpy
from rclpy.context import Context
from rclpy.node import Node

from coco_core.builder import build_application
from coco_core.deployment import Deployment, Host, LaunchOptions, deployed, drive, plan_deployment, verify
from coco_core.errors import DeploymentError
from coco_core.launcher import describe
from coco_core.model import AppSpec
from coco_core.processes.channels import plan_channels, wake_targets
from coco_core.processes.placement import LAUNCHER, Placement
from coco_core.shm import Arena
from coco_core.hosts.part import host_part
from coco_core.xml import load_application
from coco_ros.hosting import ExecutorHost
from conftest import ROOT, SHARED_DATA, run_launcher

BAXTER_BAG = ("interop_replay.xml", "baxter_teleop_replay.xml")
"""Files whose ``bag`` names a Baxter session (read at build, played by nothing here): the run's
generated one, since a fresh clone has none at the default path."""
PALPATION_WITHOUT_BAGS = {"hand": "topic", "scene": "redwood", "scene_path": str(SHARED_DATA / "rgbd" / "redwood"),
                          "registration": "fixed"}
"""config/palpation_replay.xml without its generated session (the hand from a topic, a real RGB-D
folder as the scene): the same seven processes and activities."""
FILES = sorted((ROOT / "config").glob("*.xml")) + sorted((ROOT / "test" / "data").glob("*.xml")) + [
    ROOT / "test" / "data" / "coco_original" / name for name in ("config_farm.xml", "config_latency.xml",
                                                                 "kinect_streamer.xml")
] + sorted((SHARED_DATA / "coco_xml").glob("*.xml"))
HOSTS = {"plain": LaunchOptions(), "ros": LaunchOptions(Host.ROS)}
"""The ROS host with wait sets: with ``--executor-threads`` the same rule gives the executor what it
gives wait sets here (the end-to-end tests run that option)."""

WOKEN_APP = """<package name="woken">
  <components>
    <component><name>generator</name><task>SignalGenerator</task></component>
    <component><name>filter</name><task>MovingAverage</task></component>
    <component><name>smoother</name><task>MovingAverage</task></component>
  </components>
  <connections>
    <connection data="BUFFER" policy="LOCKED" buffersize="50"><src task="generator" port="sample"/><dest task="filter" port="sample"/></connection>
    <connection data="BUFFER" policy="LOCKED" buffersize="50"><src task="filter" port="filtered"/><dest task="smoother" port="sample"/></connection>
  </connections>
  <activities>
    <process name="source">
      <activity name="ticks"><schedule type="periodic" period="10"/>
        <components><component name="generator"/></components></activity>
    </process>
    <activity name="filtering"><schedule type="triggered"/>
      <components><component name="filter"/></components></activity>
    <process name="sink">
      <activity name="smoothing"><schedule type="triggered"/>
        <components><component name="smoother"/></components></activity>
    </process>
  </activities>
</package>
"""
"""A child's periodic activity, a launcher's activity that the child wakes, and a triggered activity
of another child that the launcher's wakes."""


@pytest.fixture(scope="module")
def node():
    with pytest.MonkeyPatch.context() as env:  # the environment of the later tests stays as it was
        env.setenv("ROS_DOMAIN_ID", "152")  # read by rclpy.init: this test's own domain, this host only
        env.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        context = Context()
        rclpy.init(context=context)
    ros = Node("coco_test_deployment", context=context)
    yield ros
    ros.destroy_node()
    context.try_shutdown()


def load(path: Path, request: pytest.FixtureRequest) -> AppSpec:
    if path.name == "composite_rgbd_meshes.xml":  # its two cameras replay a palpation session
        return load_application(path, {"bag": str(request.getfixturevalue("palpation_session"))})
    if path.name in BAXTER_BAG:
        return load_application(path, {"bag": str(request.getfixturevalue("session")[0])})
    if path.name == "palpation_replay.xml":
        return load_application(path, PALPATION_WITHOUT_BAGS)
    return load_application(path, {})


def execute(spec: AppSpec, deployment: Deployment, node: Node, process: str) -> None:
    """Build ``process``'s part of ``spec`` and give it its drivers as its process does, then check
    them against ``deployment``; nothing runs."""
    part = build_application(spec, process, allow_unknown=True)
    placement = Placement.of(spec)
    eventfds: dict[str, int] = {}
    arena = Arena(f"{os.getpid()}-plan") if placement.crossing(spec) else None
    try:
        if arena is not None:
            eventfds = {name: os.eventfd(0) for name in wake_targets(plan_channels(arena, spec, placement))}
        drive(part, deployment, eventfds)
        host = ExecutorHost(node, part, deployment) if deployment.options.host is Host.ROS else None
        try:
            verify(part, deployment)
        finally:
            if host is not None:
                host.close()
    finally:
        for fd in eventfds.values():
            os.close(fd)
        if arena is not None:
            arena.close()


@pytest.mark.parametrize("host", HOSTS)
@pytest.mark.parametrize("path", FILES, ids=lambda path: path.name)
def test_every_process_executes_the_plan_check_prints(path: Path, host: str, node: Node,
                                                      request: pytest.FixtureRequest) -> None:
    if not path.exists():
        pytest.skip(f"{path} is not available")
    whole = load(path, request)
    # An application over several hosts: each host plans and runs its own part (coco_core.hosts.part).
    for spec in [host_part(whole, machine.name) for machine in whole.hosts] or [whole]:
        deployment = plan_deployment(spec, HOSTS[host])
        for process in [LAUNCHER, *(p.name for p in spec.processes)]:
            execute(spec, deployment, node, process)
        if host == "plain":  # what --check prints (it builds every part again: once is enough)
            printed = describe(spec, build_application(spec, allow_unknown=True), deployment, allow_unknown=True)
            lines = [line.strip() for line in printed.splitlines() if line.strip().startswith("activity ")]
            assert sorted(lines) == sorted(a.line() for a in deployment.activities.values())


def test_a_run_that_differs_from_its_plan_is_refused(tmp_path: Path) -> None:
    """The guard itself: a launcher that gave a driver the plan does not name stops before the run."""
    app = tmp_path / "woken.xml"
    app.write_text(WOKEN_APP)
    spec = load_application(app, {})
    part = build_application(spec)
    ros = plan_deployment(spec, LaunchOptions(Host.ROS))
    with pytest.raises(DeploymentError, match=r"wake \[\], the deployment plan \['filtering'\]"):
        drive(part, plan_deployment(spec, LaunchOptions()), {})  # the eventfd of 'filtering' is missing
    drive(part, ros, {"filtering": os.eventfd(0)})
    with pytest.raises(DeploymentError, match="activity filtering: planned .*woken by an eventfd"):
        part.activities["filtering"].driver.eventfd = None  # type: ignore[misc]  # a driver gone astray
        deployed(part, ros)


def planned_lines(check_output: str) -> set[tuple[str, str]]:
    """(process, ``activity ...`` line) of every activity in ``--check``'s tree."""
    lines, process = set(), "launcher"
    for line in check_output.splitlines():
        words = line.strip()
        if words.startswith("process "):
            process = words.split()[1]
        elif words.startswith("activity "):
            lines.add((process, words))
    return lines


def run_lines(log: str) -> set[tuple[str, str]]:
    """(process, ``activity ...`` line) of every activity each process of a run logged it runs."""
    return set(re.findall(r"\] coco(?:\[[^\]]+\])?: process (\S+): (activity .*)$", log, re.MULTILINE))


@pytest.mark.parametrize("launcher, extra", [("coco-launch", ()), ("ros", ()), ("ros", ("--executor-threads", "2")),
                                             ("ros", ("--threads", "ticks"))],
                         ids=["coco-launch", "ros", "ros executor", "ros threads"])
def test_check_prints_what_every_process_runs(launcher: str, extra: tuple[str, ...], coco_launch: Path,
                                              tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Options such as ``--executor-threads`` reach the children: their lines say so too."""
    monkeypatch.setenv("ROS_DOMAIN_ID", "152")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    script = coco_launch if launcher == "coco-launch" else ROOT / "install" / "coco_ros" / "lib" / "coco_ros" / "launcher"
    app = tmp_path / "woken.xml"
    app.write_text(WOKEN_APP)
    check = run_launcher(script, str(app), "--check", *extra)
    assert check.returncode == 0, check.stderr
    planned = planned_lines(check.stdout)
    assert {process for process, _ in planned} == {"launcher", "source", "sink"}, check.stdout
    run = run_launcher(script, str(app), "--duration", "0.5", *extra)
    assert run.returncode == 0, run.stderr
    assert run_lines(run.stdout + run.stderr) == planned, run.stderr
    if extra[:1] == ("--executor-threads",):
        assert ("source", "activity ticks: periodic 10 ms -> executor (rclpy timer in its callback group)") in planned, \
            check.stdout


def test_the_real_time_haptic_application_runs_as_checked(coco_launch: Path, tmp_path: Path) -> None:
    """A 1 ms loop alone in a real-time process beside the launcher's recorder."""
    check = run_launcher(coco_launch, "haptic_implicit", "--check")
    assert check.returncode == 0, check.stderr
    run = run_launcher(coco_launch, "haptic_implicit", f"out:={tmp_path}", "--duration", "0.5", timeout=120)
    assert run.returncode == 0, run.stderr
    assert run_lines(run.stdout + run.stderr) == planned_lines(check.stdout), run.stderr
