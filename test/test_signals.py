"""Signals at any moment of a launch (issue: Ctrl-C during start-up was swallowed, a second Ctrl-C
aborted in native code and lost the contact sheet, SIGTERM during start-up killed silently).

The rules (coco_core.signals, README's exit statuses): a signal before the application runs ends
the launch with 128 + its number and nothing started; while it runs, the first Ctrl-C or SIGTERM
stops it cleanly within a second (status 0) with its outputs flushed; a second Ctrl-C lets that
stop finish and leaves at once with 130, a second SIGTERM changes nothing. Never a negative status
(killed by a signal), an abort or a hang (SIGINT then SIGTERM, as ``ros2 launch`` sends them, once
hung the ROS launcher for good), and no child process or /dev/shm segment outlives the launcher.
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
from pathlib import Path

import pytest

from conftest import DEMO_APP, ROOT, read_rows, start_launcher
from test_baxter_app import APP as BAXTER_APP

DELAYS = [0.2, 1.1, 3.4]
"""Seconds from the moment the launcher's signal handling is in force to the signal: while the
runtime is imported, while the file is read and components are built, and while it runs (the demo
starts in about 1-2 s here). Each stage is also signalled on purpose, in bursts, below."""


def wait_for_mask(process: subprocess.Popen[str], field: str, signum: int, present: bool, within: float) -> bool:
    """Wait until ``signum``'s bit in ``process``'s /proc ``field`` mask (``SigCgt``: caught,
    ``ShdPnd``: pending) is ``present``; False when it did not come to that within ``within`` s or
    the process ended."""
    status = Path(f"/proc/{process.pid}/status")
    deadline = time.monotonic() + within
    while time.monotonic() < deadline and process.poll() is None:
        try:
            mask = next(line for line in status.read_text().splitlines() if line.startswith(f"{field}:"))
        except OSError:
            return False  # it ended
        if bool(int(mask.split()[1], 16) >> (signum - 1) & 1) == present:
            return True
        time.sleep(0.001)
    return False


def handling_in_force(process: subprocess.Popen[str], within: float = 30.0) -> None:
    """Wait until ``process`` catches SIGTERM (/proc's ``SigCgt`` mask): the first lines of the
    installed script, which take SIGINT and then SIGTERM over, have run. Before them the interpreter
    is still starting (its own modules and ``site``), where no program has a say: a SIGTERM there ends
    it by the kernel's default action (status -15), a SIGINT with Python's KeyboardInterrupt. That
    window is ~0.1 s on a quiet machine and was over 0.3 s on a loaded one (a launcher killed at
    0.3 s, before its handling, failed this test)."""
    if wait_for_mask(process, "SigCgt", signal.SIGTERM, True, within):
        return
    raise AssertionError(f"the launcher's signal handling was not in force within {within:g} s "
                         f"(status {process.poll()})")


def launchers() -> list[Path]:
    return [ROOT / "install" / "coco_core" / "lib" / "coco_core" / "coco-launch",
            ROOT / "install" / "coco_ros" / "lib" / "coco_ros" / "launcher"]


@pytest.fixture(autouse=True)
def ros_domain(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", "66")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


@pytest.mark.parametrize("launcher", launchers(), ids=["coco-launch", "ros-launcher"])
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_at_any_moment_ends_the_launch_cleanly(launcher: Path, signum: int, tmp_path: Path) -> None:
    for delay in DELAYS:
        output = tmp_path / f"run_{delay}.csv"
        process = start_launcher(launcher, DEMO_APP, f"output:={output}", "--duration", "60")
        handling_in_force(process)
        time.sleep(delay)
        sent = time.monotonic()
        process.send_signal(signum)
        out, _ = process.communicate(timeout=30)
        took = time.monotonic() - sent
        code = process.returncode
        assert code in (0, 128 + signum), f"{delay} s: status {code}\n{out}"
        assert took < 3.0, f"{delay} s: stopped {took:.1f} s after the signal\n{out}"  # 1 s + interpreter exit
        assert "Traceback" not in out and "terminate called" not in out, f"{delay} s:\n{out}"
        if code == 128 + signum:
            assert "before the application started" in out, out
            assert not output.exists(), "nothing ran, nothing was written"
        else:
            assert "(clean)" in out, out
            if not output.exists():  # the signal came before the first cycle (a loaded machine)
                assert "before it ran: no activity had cycled" in out, out
                continue
            rows = read_rows(output)  # flushed: complete rows only
            assert all(row["value"] not in (None, "") for row in rows), rows[-1:]


def test_a_second_ctrl_c_during_the_stop_keeps_the_outputs(coco_launch: Path, session, tmp_path: Path) -> None:
    folder, _ = session
    output = tmp_path / "teleop"
    process = subprocess.Popen([str(coco_launch), BAXTER_APP, f"bag:={folder}", f"output:={output}"], cwd=ROOT,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    video = output / "frames.mp4"
    deadline = time.monotonic() + 60
    while not (video.exists() and video.stat().st_size > 0) and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(1.0)
    process.send_signal(signal.SIGINT)
    time.sleep(0.02)
    process.send_signal(signal.SIGINT)
    out, _ = process.communicate(timeout=30)
    assert process.returncode == 130, f"status {process.returncode}\n{out}"
    assert "terminate called" not in out and "Traceback" not in out, out
    assert (output / "contact_sheet.png").stat().st_size > 0, "the contact sheet was written"
    assert (output / "summary.json").exists(), "the summary was written"


def slow_application(folder: Path, args: int = 1000) -> Path:
    """An application whose file takes minutes to read: each arg's ``$(eval)`` upper-cases 20
    strings of a million characters (well within the expression limits: a fraction of a second)."""
    expression = "max(" + ", ".join(["len(('x' * 999999).upper())"] * 20) + ")"
    declarations = "".join(f'<arg name="a{index}" default="$(eval {expression})"/>\n' for index in range(args))
    path = folder / "slow.xml"
    path.write_text(f"<package>\n{declarations}</package>\n")
    return path


@pytest.mark.parametrize("launcher", launchers(), ids=["coco-launch", "ros-launcher"])
@pytest.mark.parametrize("signum, then", [(signal.SIGINT, signal.SIGTERM), (signal.SIGTERM, signal.SIGINT)],
                         ids=["SIGINT+SIGTERM", "SIGTERM+SIGINT"])
def test_a_burst_of_signals_ends_a_slow_load_at_once(launcher: Path, signum: int, then: int, tmp_path: Path) -> None:
    process = start_launcher(launcher, str(slow_application(tmp_path)), "--log-level", "DEBUG", "--duration", "1")
    watchdog = threading.Timer(30, process.kill)  # no 'reading' line: do not wait minutes for the load
    watchdog.start()
    try:
        assert process.stdout is not None
        lines = []
        for line in process.stdout:  # the launcher says when it starts reading the file
            lines.append(line)
            if "coco: reading " in line:
                break
        else:
            pytest.fail("".join(lines))
        burst(process, signum, then)
        out, _ = process.communicate(timeout=15)  # the load alone takes minutes
    finally:
        watchdog.cancel()
        process.kill()
    assert process.returncode == 128 + signum, out
    assert "before the application started" in out and "Traceback" not in out, out


def delivered(process: subprocess.Popen[str], signum: int, within: float = 5.0) -> None:
    """Wait until ``signum`` is no longer pending for ``process`` (/proc's ``ShdPnd``): a second one
    sent before would merge with it in the kernel, and the launcher could not tell that two came."""
    wait_for_mask(process, "ShdPnd", signum, False, within)


def burst(process: subprocess.Popen[str], *signals: int, group: bool = False) -> None:
    """Send ``signals`` to ``process`` (``group``: to its process group, children included, as a
    service manager does) as fast as each is taken."""
    for signum in signals:
        if group:
            os.killpg(process.pid, signum)
        else:
            process.send_signal(signum)
        delivered(process, signum)


def children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (a launcher's child processes)."""
    found = []
    for entry in Path("/proc").iterdir():
        try:
            if entry.name.isdigit() and int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                found.append(int(entry.name))
        except (OSError, IndexError, ValueError):
            continue
    return found


def gone(pids: list[int], launcher: int, within: float = 3.0) -> list[str]:
    """What of a launcher is still there ``within`` seconds after it ended (an orphaned child sweeps
    its segments a second after its launcher's death): child processes and /dev/shm segments."""
    deadline = time.monotonic() + within
    while True:
        left = [f"child {pid}" for pid in pids if Path(f"/proc/{pid}").exists()
                and Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"]
        left += [f"/dev/shm/{name}" for name in os.listdir("/dev/shm") if name.startswith(f"coco.{launcher}-")]
        if not left or time.monotonic() > deadline:
            return left
        time.sleep(0.02)


STAGES_APP = ROOT / "test" / "data" / "signal_stages.xml"
INT, TERM = signal.SIGINT, signal.SIGTERM


@pytest.mark.parametrize("launcher", launchers(), ids=["coco-launch", "ros-launcher"])
@pytest.mark.parametrize("stage, first, second, status, group", [
    ("building", TERM, INT, 143, False),  # before the application ran: the first signal's status, nothing started
    ("configuring", INT, TERM, 0, False),  # ros2 launch's order: a clean stop (before any cycle ran)
    ("running", INT, TERM, 0, False),  # a second SIGTERM changes nothing
    ("running", INT, INT, 130, False),  # a second Ctrl-C: the stop finishes, then the launcher leaves
    ("running", TERM, TERM, 0, True),  # the child gets both too: it stops with the launcher's word
    ("stopping", INT, INT, 130, False),  # the second while on_stop lingers
    ("stopping", TERM, TERM, 0, False),
], ids=["building-TERM+INT", "configuring-INT+TERM", "running-INT+TERM", "running-INT+INT", "running-group-TERM+TERM",
        "stopping-INT+INT", "stopping-TERM+TERM"])
def test_a_burst_of_signals_at_each_stage(launcher: Path, stage: str, first: int, second: int, status: int,
                                          group: bool) -> None:
    """Two signals in quick succession, at the stage the application's component says it is at
    (the launcher's configures while the child's waits configured; "stopping": the first signal
    began the stop): the documented status, within the second a stop takes, and nothing left."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1",
           "PYTHONPATH": f"{STAGES_APP.parent}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    process = subprocess.Popen([str(launcher), str(STAGES_APP), f"linger:={stage}", "--duration", "30"], cwd=ROOT,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
                               start_new_session=group)
    watchdog = threading.Timer(60, process.kill)  # a hang fails the test instead of holding the suite
    watchdog.start()
    try:
        assert process.stdout is not None
        lines = []
        marker = f"stage here: {'running' if stage == 'stopping' else stage}"
        for line in process.stdout:
            lines.append(line)
            if marker in line:
                break
        else:
            pytest.fail(f"never at {marker!r}:\n{''.join(lines)}")
        pids = children(process.pid)
        sent = time.monotonic()
        if stage == "stopping":
            burst(process, first)
            for line in process.stdout:
                lines.append(line)
                if "stage here: stopping" in line:
                    break
            burst(process, second)
        else:
            burst(process, first, second, group=group)
        out, _ = process.communicate(timeout=30)
        took = time.monotonic() - sent
    finally:
        watchdog.cancel()
        process.kill()
    out = "".join(lines) + out
    assert process.returncode == status, f"status {process.returncode}, expected {status}\n{out}"
    assert took < 4.0, f"ended {took:.1f} s after the first signal\n{out}"  # a stop's second + interpreters' exits
    assert "Traceback" not in out and "did not stop" not in out, out
    assert not gone(pids, process.pid), f"left behind: {gone(pids, process.pid, 0)}\n{out}"
