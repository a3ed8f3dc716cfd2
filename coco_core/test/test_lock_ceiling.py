"""The interpreter lock's ceiling (coco_core.lock_ceiling): in a ``<process>`` with a real-time
activity, the process's other threads run in SCHED_FIFO at priority 1 and the switch interval is
0.1 ms, so that a thread holding the lock the loop waits for is never preempted by the machine's
normal work (issue 34: the haptic loop waited 3-10 ms for the structures' relay); a process without
one keeps CPython's defaults. Real child processes of the launcher, as in test_processes_lifecycle."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from coco_core.lock_ceiling import CEILING_PRIORITY, SWITCH_INTERVAL, raise_lock_holders

DATA = Path(__file__).parent / "data"

APP = """<package name="ceiling">
  <components>
    <component><name>loop</name><task>process_components:SchedulingProbe</task>
      <attributes><attribute name="path" value="{tmp}/loop.json"/></attributes></component>
    <component><name>other</name><task>process_components:SchedulingProbe</task>
      <attributes><attribute name="path" value="{tmp}/other.json"/>
        <attribute name="stop_after_probe" value="true"/></attributes></component>
  </components>
  <activities>
    <process name="haptics">
      <activity name="loop"><schedule type="periodic" period="1" {loop}/>
        <components><component name="loop"/></components></activity>
      <activity name="other"><schedule type="periodic" period="20"/>
        <components><component name="other"/></components></activity>
    </process>
  </activities>
</package>
"""


def run(tmp: Path, loop: str) -> str:
    app = tmp / "app.xml"
    app.write_text(APP.format(tmp=tmp, loop=loop))
    env = dict(os.environ, PYTHONPATH=f"{DATA}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    done = subprocess.run([sys.executable, "-m", "coco_core.launcher", str(app), "--duration", "60"], env=env,
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=90)
    assert done.returncode == 0, done.stdout
    return done.stdout


def fifo_allowed() -> bool:
    """Whether this thread may enter SCHED_FIFO (root or CAP_SYS_NICE, and a real-time budget)."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
    except OSError:
        return False
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    return True


def test_the_other_threads_of_a_realtime_process_hold_the_lock_above_normal_work(tmp_path: Path) -> None:
    out = run(tmp_path, 'realtime="FIFO" priority="80"')
    loop, other = (json.loads((tmp_path / f"{name}.json").read_text()) for name in ("loop", "other"))
    if not fifo_allowed():
        assert "refused by the OS" in out, out
        assert not other["fifo"]
        return
    assert (loop["fifo"], loop["priority"]) == (True, 80)
    assert (other["fifo"], other["priority"]) == (True, CEILING_PRIORITY), out
    assert other["switch_interval"] == pytest.approx(SWITCH_INTERVAL)
    assert "interpreter lock's switch interval 0.1 ms" in out, out


def test_a_process_without_a_realtime_activity_keeps_the_defaults(tmp_path: Path) -> None:
    out = run(tmp_path, "")
    other = json.loads((tmp_path / "other.json").read_text())
    assert (other["fifo"], other["switch_interval"]) == (False, pytest.approx(0.005)), out


def test_a_loop_at_the_lowest_priority_leaves_no_room_below_it() -> None:
    applied, warnings = raise_lock_holders([CEILING_PRIORITY])
    assert not applied and "no real-time priority below it" in warnings[0]
    assert raise_lock_holders([]) == (False, [])
