"""Thread placement of activities: affinity, exclusive cores, real-time class, nice value.

What the OS allows is applied to the activity's own thread; what it refuses becomes one clear warning
and the activity runs anyway.
"""

from __future__ import annotations

import logging
import os
import threading

import pytest

from coco_core import Application, Component, PeriodicActivity, SchedulingRequest, TriggeredActivity
from coco_core.builder import build_application
from coco_core.registry import register
from coco_core.xml import parse_application_string

pytestmark = pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="Linux scheduling calls only")


class Probe(Component):
    """Records, in its activity's thread, where and how that thread is scheduled."""

    def init(self) -> None:
        self.seen = threading.Event()
        self.cores: set[int] = set()
        self.policy = -1
        self.nice = 0

    def on_config(self) -> None:
        self.cores = os.sched_getaffinity(0)
        self.policy = os.sched_getscheduler(0)
        self.nice = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
        self.seen.set()


def run_probe(request: SchedulingRequest, *others: tuple[str, SchedulingRequest]) -> Probe:
    app = Application("scheduling")
    probe = app.add(Probe("probe"), TriggeredActivity("probed", scheduling=request))
    for name, other in others:
        app.add(Probe(f"{name}_probe"), TriggeredActivity(name, scheduling=other))
    app.start()
    try:
        assert probe.seen.wait(5.0)
    finally:
        app.stop()
    return probe


def test_affinity_pins_the_activity_thread_only() -> None:
    before = os.sched_getaffinity(0)
    probe = run_probe(SchedulingRequest(affinity=[min(before)]))
    assert probe.cores == {min(before)}
    assert os.sched_getaffinity(0) == before, "the launcher's own thread must keep its cores"


def test_a_core_that_does_not_exist_is_a_warning_and_the_activity_runs(caplog) -> None:
    caplog.set_level(logging.WARNING, logger="coco")
    probe = run_probe(SchedulingRequest(affinity=[999]))
    assert probe.seen.is_set()
    warning = " ".join(record.getMessage() for record in caplog.records)
    assert "activity probed" in warning and "[999] not available" in warning
    assert str(sorted(os.sched_getaffinity(0))) in warning


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs two cores to reserve one")
def test_exclusive_cores_keep_other_activities_off_them() -> None:
    cores = sorted(os.sched_getaffinity(0))
    probe = run_probe(SchedulingRequest(), ("exclusive", SchedulingRequest(affinity=[cores[0]], exclusive=True)))
    assert cores[0] not in probe.cores and probe.cores == set(cores[1:])


def test_priority_without_a_realtime_class_is_ignored_with_a_warning(caplog) -> None:
    caplog.set_level(logging.WARNING, logger="coco")
    run_probe(SchedulingRequest(priority=5))
    assert any("priority 5 ignored" in record.getMessage() for record in caplog.records)


def test_realtime_fifo_is_applied_or_refused_with_a_warning(caplog) -> None:
    caplog.set_level(logging.WARNING, logger="coco")
    probe = run_probe(SchedulingRequest(realtime="FIFO", priority=10))
    refused = [r.getMessage() for r in caplog.records if "realtime FIFO priority 10" in r.getMessage()]
    if probe.policy == os.SCHED_FIFO:
        assert not refused
    else:  # no CAP_SYS_NICE here (e.g. a container): the thread stays normal and the user is told why
        assert probe.policy == os.SCHED_OTHER
        assert refused and "refused by the OS" in refused[0] and "CAP_SYS_NICE" in refused[0]


def test_nice_value_is_applied_to_the_activity_thread_only() -> None:
    before = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    probe = run_probe(SchedulingRequest(nice=min(before + 7, 19)))
    assert probe.nice == min(before + 7, 19)
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == before


def test_schedule_attributes_of_a_file_reach_the_activity() -> None:
    register("SchedulingProbe")(Probe)
    spec = parse_application_string("""<package>
      <components><component><name>p</name><task>SchedulingProbe</task></component></components>
      <activities>
        <activity name="fast">
          <schedule type="periodic" value="2" exclusive_affinity="0" realtime="RR" priority="20" nice="-2"/>
          <components><component name="p"/></components>
        </activity>
      </activities>
    </package>""", filename="scheduling.xml")
    app = build_application(spec)
    activity = app.activity("fast")
    assert isinstance(activity, PeriodicActivity) and activity.period == pytest.approx(0.002)
    request = activity.scheduling
    assert (request.affinity, request.exclusive, request.realtime, request.priority, request.nice) == (
        [0], True, "RR", 20, -2)


def test_check_prints_what_each_activity_asks_of_the_os() -> None:
    """``--check``'s line of an activity (and the line each process logs) names its spin and its
    thread's settings beside the schedule: a real-time loop's settings are what its user checks."""
    from coco_core.deployment import plan_deployment

    spec = parse_application_string("""<package>
      <activities>
        <activity name="haptics"><schedule period="1" spin="0.6" realtime="FIFO" priority="80"/><components/></activity>
        <activity name="pinned"><schedule period="10" exclusive_affinity="1" nice="5"/><components/></activity>
        <activity name="shared"><schedule type="triggered" affinity="0,1"/><components/></activity>
        <activity name="plain"><schedule period="10"/><components/></activity>
        <activity name="view"><schedule type="triggered" min_period="16" nice="10"/><components/></activity>
      </activities>
    </package>""", filename="asks.xml")
    lines = [activity.line() for activity in plan_deployment(spec).host().activities.values()]
    assert lines == ["activity haptics: periodic 1 ms, spin 0.6 ms, SCHED_FIFO priority 80 -> own thread",
                     "activity pinned: periodic 10 ms, nice 5, exclusive cores 1 -> own thread",
                     "activity shared: triggered, cores 0,1 -> own thread",
                     "activity plain: periodic 10 ms -> own thread",
                     "activity view: triggered, at most every 16 ms, nice 10 -> own thread"]


def test_a_process_real_time_class_is_its_activities_summed_up_and_check_prints_it() -> None:
    """A process's real-time class is the plan's summary of its activities' (the highest, and who
    asks), on its ``--check`` line before its own settings, with the interpreter lock's ceiling that
    its child applies from it: a ``<process>``'s whose loops leave room below them, never the
    launcher's. A process whose threads all run in the normal class has none, and a one-process
    application still lists its activities alone."""
    from coco_core.deployment import plan_deployment

    spec = parse_application_string("""<package>
      <activities>
        <process name="haptics" lock_memory="true">
          <activity name="io"><schedule period="10" realtime="RR" priority="90"/><components/></activity>
          <activity name="loop"><schedule period="1" realtime="FIFO" priority="80"/><components/></activity>
          <activity name="log"><schedule period="100"/><components/></activity>
        </process>
        <process name="lowest"><activity name="slow"><schedule period="5" realtime="FIFO"/><components/></activity></process>
        <process name="view"><activity name="draw"><schedule period="20"/><components/></activity></process>
      </activities>
    </package>""", filename="classes.xml")
    deployment = plan_deployment(spec)
    haptics, lowest = deployment.host().process("haptics").realtime, deployment.host().process("lowest").realtime
    assert haptics is not None and lowest is not None and deployment.host().process("view").realtime is None
    assert (haptics.policy, haptics.priority, haptics.activities, haptics.priorities, haptics.ceiling) == (
        "RR", 90, ("io", "loop"), (90, 80), True)
    assert (lowest.priority, lowest.priorities, lowest.ceiling) == (None, (1,), False), "no room below priority 1"
    text = deployment.render()
    assert ("process haptics (real-time SCHED_RR priority 90 (io, loop), other threads SCHED_FIFO 1 (the lock's "
            "ceiling), memory locked)") in text, text
    assert "process lowest (real-time SCHED_FIFO (slow))" in text and "process view\n" in text, text
    alone = parse_application_string("""<package><activities>
        <activity name="loop"><schedule period="1" realtime="FIFO" priority="80"/><components/></activity>
      </activities></package>""", filename="alone.xml")
    launcher = plan_deployment(alone).host().process("").realtime
    assert launcher is not None and not launcher.ceiling, "the launcher's own process never takes the ceiling"
    tree = plan_deployment(alone).render()
    assert "process" not in tree and "activity loop: periodic 1 ms, SCHED_FIFO priority 80 -> own thread" in tree, tree
