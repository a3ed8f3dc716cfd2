"""The launcher's signal handling at the ends of a launch (coco_core.signals): a signal while the
interpreter exits must not kill the process (Python gives SIGINT its default action back as it tears
itself down: a Ctrl-C then ended the launcher by the signal, status -2 for its parent)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent("""
    import os, signal, sys, time
    from coco_core.signals import LaunchSignals

    signals = LaunchSignals().install()
    status = signals.finish({status})
    if {now}:
        os.kill(os.getpid(), signal.SIGINT)  # handled at once, in the main thread
        time.sleep(5)


    class LastWords:
        # Runs while the modules are torn down, after Python gave the signals their default action back.
        def __del__(self):
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)


    last_words = LastWords()
    sys.exit(status)
""")


def run_script(status: int, now: bool) -> int:
    completed = subprocess.run([sys.executable, "-c", SCRIPT.format(status=status, now=now)], timeout=60,
                               capture_output=True, text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    assert "Traceback" not in completed.stderr, completed.stderr
    return completed.returncode


@pytest.mark.parametrize("status", [0, 1])
def test_a_ctrl_c_while_the_interpreter_tears_down_leaves_the_launch_status(status: int) -> None:
    assert run_script(status, now=False) == status  # not -2: killed by the signal


def test_a_ctrl_c_after_the_launch_finished_leaves_at_once_with_130() -> None:
    assert run_script(0, now=True) == 128 + signal.SIGINT


HELD = textwrap.dedent("""
    import os, signal
    from coco_core import Application
    from coco_core.signals import LaunchSignals

    signals = LaunchSignals().install()
    app = Application("held")
    signals.attach(app)
    # The main thread holds a lock of the stop's path (the start gate's), as it did inside the stop
    # that a first signal's handler ran when a second came: handlers run in the main thread.
    with app.gate._lock:
        os.kill(os.getpid(), signal.SIGINT)
        os.kill(os.getpid(), signal.SIGTERM)
        handled = len(signals.received)  # both handlers ran before this line, in this thread
    print("handled", handled, flush=True)
    print("stop requested:", app.wait(5), app.stop_reason, flush=True)
""")


def test_a_signal_never_waits_for_a_lock_that_the_interrupted_thread_holds() -> None:
    """The ROS launcher hung for good on SIGINT then SIGTERM: the second handler waited for the
    lock (an activity driver's, around rclpy's Timer.reset) that the first one's stop held, in the
    same thread. Handlers now only record; the stop runs in a thread of its own, which waits for the
    lock like any other thread."""
    try:
        completed = subprocess.run([sys.executable, "-c", HELD], timeout=20, capture_output=True, text=True)
    except subprocess.TimeoutExpired as hung:
        pytest.fail(f"the handler waited for the lock its own thread holds (hung):\n{hung.stdout!r}")
    assert completed.returncode == 0, completed.stderr
    assert "handled 2" in completed.stdout and "stop requested: True received SIGINT" in completed.stdout, \
        completed.stdout + completed.stderr

