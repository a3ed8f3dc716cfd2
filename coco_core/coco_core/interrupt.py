"""Stopping a child process the way a user does: Ctrl-C, then wait.

Tests, benchmarks and tools run launchers and ROS peers in processes of their own; they stop them
with SIGINT so that the clean-shutdown path (flush, close bags, destroy nodes) is what runs, and
fall back to SIGKILL only when that path hangs, which the caller then sees as exit code -9.
"""

from __future__ import annotations

import signal
import subprocess

KILLED = -9
"""Exit code reported for a process that ignored Ctrl-C for the whole timeout and was killed."""


def interrupt(process: subprocess.Popen[str], timeout: float = 20.0) -> tuple[int, str]:
    """Ctrl-C ``process`` if it still runs, wait up to ``timeout`` s; its exit code and its output
    (stdout, which callers usually merge stderr into; empty when it was not piped)."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
    try:
        output, _ = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        output, _ = process.communicate()
        return KILLED, output or ""
    return process.returncode, output or ""
