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
