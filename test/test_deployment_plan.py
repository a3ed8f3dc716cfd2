"""One deployment plan: what ``--check`` prints is what every process of the run executes.

Two levels. In-process, for every application file of the workspace (``config/``, the test
applications, the original CoCo samples) and both hosts (plain, ROS): each process's part is built
as its process builds it from the plan, given the drivers the launchers give it (the eventfds of the
plan's wake sets, the ROS host's wait sets on a real node), and checked against the plan, and
``Deployment.render`` (``--check``'s tree) shows the plan's line for every activity of every host.
End to end, on applications with child processes: both launchers' ``--check`` lines equal the lines
each process logs when it runs (with ``--executor-threads`` and ``--threads`` too), and with
``--host`` they print that host's part of the plan.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import rclpy
from rclpy.context import Context
from rclpy.node import Node

from coco_core.builder import build_application
from coco_core.application import Application
from coco_core.deployment import PLAIN, ActivityFacts, HostDeployment, drive, plan_deployment
from coco_core.model import AppSpec
from coco_core.wakeup import Wakeup
from coco_core.xml import load_application
from coco_ros.deployment import ExecutorPlan, RosRules
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
HOSTS = {"plain": PLAIN, "ros": RosRules()}
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


def execute(deployment: HostDeployment, node: Node, process: str) -> Application:
    """Build ``process``'s part of the host's plan and give it its drivers as its process does (the
    eventfds of the plan's wake sets, the ROS host's wait sets or executor on a real node), then
    check them and the built activities against the plan; nothing runs. The part, for ``--check``."""
    part = build_application(deployment.spec, process, allow_unknown=True, placement=deployment.placement)
    eventfds = {name: Wakeup.new() for name in deployment.woken}
    try:
        drive(part, deployment, eventfds)
        host = ExecutorHost(node, part, deployment) if isinstance(deployment.process(process).host, ExecutorPlan) else None
        try:
            for name in deployment.process(process).activities:
                planned, activity = deployment.activities[name], part.activities[name]
                assert ActivityFacts.of_activity(activity) == planned.facts, planned.line()
                driver = activity.driver
                assert (driver.driving, driver.eventfd is not None) == (planned.driving, planned.eventfd), planned.line()
        finally:
            if host is not None:
                host.close()
    finally:
        for wakeup in eventfds.values():
            wakeup.close()
    return part


@pytest.mark.parametrize("host", HOSTS)
@pytest.mark.parametrize("path", FILES, ids=lambda path: path.name)
def test_every_process_executes_the_plan_check_prints(path: Path, host: str, node: Node,
                                                      request: pytest.FixtureRequest) -> None:
    if not path.exists():
        pytest.skip(f"{path} is not available")
    spec = load(path, request)
    # An application over several hosts: each host (--host) runs its own part of the one plan.
    deployment = plan_deployment(spec, HOSTS[host])
    parts = {name: {process: execute(planned, node, process) for process in planned.processes}
             for name, planned in deployment.hosts.items()}
    printed = deployment.render(parts)  # what --check prints, from the parts built and driven here
    assert planned_lines(printed) == {(process or "launcher", placed.line()) for planned in deployment.hosts.values()
                                      for process in planned.processes for placed in planned.of_process(process)}, printed


def planned_lines(check_output: str) -> set[tuple[str, str]]:
    """(process, ``activity ...`` line) of every activity in ``--check``'s tree."""
    lines, process = set(), "launcher"
    for line in check_output.splitlines():
        words = line.strip()
        if words.startswith("application "):  # the next host's tree
            process = "launcher"
        elif words.startswith("process "):
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


@pytest.mark.parametrize("launcher", ["coco-launch", "ros"])
def test_check_with_host_prints_that_hosts_part_of_the_plan(launcher: str, coco_launch: Path,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", "152")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    script = coco_launch if launcher == "coco-launch" else ROOT / "install" / "coco_ros" / "lib" / "coco_ros" / "launcher"
    path = ROOT / "config" / "hosts_demo_pipeline.xml"
    spec = load_application(path, {})
    host = spec.hosts[-1].name
    check = run_launcher(script, str(path), "--check", "--host", host)
    assert check.returncode == 0, check.stderr
    planned = plan_deployment(spec, HOSTS["plain" if launcher == "coco-launch" else "ros"], host).host(host)
    assert planned_lines(check.stdout) == {(process or "launcher", placed.line()) for process in planned.processes
                                           for placed in planned.of_process(process)}, check.stdout
