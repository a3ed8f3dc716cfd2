"""CPU share in the profile: per process, and per thread, so that a busy wait shows by its name."""

from __future__ import annotations

import os
import subprocess
import sys
import time

from coco_core import Component, PeriodicActivity
from coco_core.cpu import application_cpu, process_cpu, thread_cpu
from coco_core.report import render, snapshot

SPIN_CPU = 0.15
"""CPU seconds the spinning activity burns in all: 15 ticks of /proc's 10 ms, far above its noise."""


class Spin(Component):
    """Busy-waits through its first updates until its thread used ``SPIN_CPU`` seconds of CPU."""

    def init(self) -> None:
        self.done = False

    def on_update(self) -> None:
        while not self.done and time.thread_time() < SPIN_CPU:
            pass
        self.done = True


class Idle(Component):
    def on_update(self) -> None:
        pass


def test_the_profile_shows_each_threads_cpu_and_the_spinner_first(make_app, wait_until) -> None:
    app = make_app("cpu")
    spin = app.add(Spin("spin"), PeriodicActivity("spinning", 0.01))
    app.add(Idle("idle"), PeriodicActivity("idling", 0.01))
    app.start()
    assert wait_until(lambda: spin.done, timeout=60.0)
    shot = snapshot(app)
    threads = {row[0]: (float(row[1]), float(row[2])) for row in shot.threads}
    assert threads["coco:spinning"][0] >= SPIN_CPU - 0.02, shot.threads
    assert threads.get("coco:idling", (0.0, 0.0))[0] < threads["coco:spinning"][0], shot.threads
    activity_rows = [row for row in shot.threads if row[0].startswith("coco:")]
    assert activity_rows[0][0] == "coco:spinning", "busiest first"
    assert shot.cores is not None and 0 < shot.cores
    text = render(app.name, [shot])
    assert "cpu cores" in text and "coco:spinning" in text, text
    assert f"all processes: {shot.cores:.2f} cores" in text, text


def test_a_process_that_is_gone_has_no_cpu_and_a_live_one_its_own() -> None:
    done = subprocess.Popen(["true"])
    assert done.wait(timeout=30) == 0
    assert process_cpu(done.pid) is None, "reaped: no /proc entry"
    mine = process_cpu()
    assert mine is not None and mine.seconds > 0 and mine.wall > 0
    assert any(name == "MainThread" for name, _ in thread_cpu())


def test_the_profile_at_exit_keeps_the_cpu_of_the_threads_that_ended(make_app, wait_until) -> None:
    """The final profile is taken after the activities' threads ended, when /proc lists them no more:
    each driver records its thread's CPU when it ends."""
    app = make_app("cpu_at_exit")
    spin = app.add(Spin("spin"), PeriodicActivity("spinning", 0.01))
    app.start()
    assert wait_until(lambda: spin.done, timeout=60.0)
    assert app.stop()
    shot = snapshot(app)
    threads = {row[0]: float(row[1]) for row in shot.threads}
    assert "coco:spinning" not in threads, shot.threads
    assert threads["coco:spinning (ended)"] >= SPIN_CPU - 0.02, shot.threads
    row = next(row for row in shot.activities if row[0] == "spinning")
    assert row[5] != "-" and float(row[5]) > 0, row


def test_the_applications_cpu_names_each_child_by_its_process_even_past_the_os_limit() -> None:
    """A child of the process level calls itself ``coco:<process>``, cut by the OS at 15 bytes; any
    other process under the launcher (an encoder a component started) is named by its command."""
    named = subprocess.Popen([sys.executable, "-c", "import ctypes, sys; "
                              "ctypes.CDLL(None).prctl(15, b'coco:averylongprocessname'[:15], 0, 0, 0); "
                              "print('named', flush=True); sys.stdin.read()"],
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    other = subprocess.Popen(["sleep", "60"])
    try:
        assert named.stdout is not None and named.stdout.readline().strip() == "named"
        shares = application_cpu(os.getpid(), {"averylongprocessname", "short"})
        assert "averylongprocessname" in shares, shares
        assert "[sleep]" in shares, shares
        assert set(shares) >= {"launcher"} and all(cores >= 0 for cores in shares.values())
    finally:
        other.kill()
        other.wait()
        assert named.stdin is not None
        named.stdin.close()
        named.wait(timeout=30)
