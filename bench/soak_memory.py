"""Soak of memory in long runs: the Baxter replay looped for minutes, the RSS of every process sampled.

Issue 23 measured the app with its bag looped for ten minutes growing linearly, about 5 MB a minute
in the launcher and in the view process, with no plateau. Two causes were found: the summary kept
every latency it saw (a list of floats, and the allocator pages they pinned), and the display's
latency crossed processes in a 65,536-slot ring of shared memory (270 MB) that the run touched page by
page. This soak runs the installed ``coco-launch`` on ``config/baxter_teleop_replay.xml loop:=true``,
samples each process's anonymous and shared-memory RSS (``/proc/PID/status``: RssAnon, RssShmem), and
fits a line to the samples after the warm-up. The anchor is the growth the issue measured.

    .venv/bin/python bench/soak_memory.py                  # 10 minutes, the view on
    .venv/bin/python bench/soak_memory.py --minutes 3 --display false --rate 0

Exit status 1 when a process grows faster than ``--limit`` MB a minute (a linear trend) after the
warm-up; the table says which process and which kind of memory.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import _report
from _table import Table, verdict

APP = _report.REPO / "config" / "baxter_teleop_replay.xml"
INSTALL = _report.REPO / "install"
ANCHOR_MB_PER_MIN = 5.0
"""The growth issue 23 measured in the launcher and in the view process (MB a minute, each)."""
WARM_UP = 0.25
"""The share of the run left out of the trend: imports, first frames, allocator arenas filling."""


@dataclass
class Trace:
    """The RSS samples of one process of the application."""

    name: str
    times: list[float] = field(default_factory=list)
    anon_mb: list[float] = field(default_factory=list)
    shmem_mb: list[float] = field(default_factory=list)

    def slope(self, values: list[float]) -> float:
        """MB a minute of the least-squares line through the samples after the warm-up."""
        start = int(len(self.times) * WARM_UP)
        t, v = np.array(self.times[start:]), np.array(values[start:])
        if len(t) < 3 or np.ptp(t) == 0:
            return float("nan")
        return float(np.polyfit(t / 60.0, v, 1)[0])


def rss(pid: int) -> tuple[float, float] | None:
    """(RssAnon, RssShmem) of ``pid`` in MB, or None once it ended."""
    try:
        lines = Path(f"/proc/{pid}/status").read_text().splitlines()
    except OSError:
        return None
    fields = {line.split(":")[0]: line.split()[1] for line in lines if line.startswith(("RssAnon", "RssShmem"))}
    return int(fields.get("RssAnon", 0)) / 1024, int(fields.get("RssShmem", 0)) / 1024


def process_name(pid: int, launcher: int) -> str:
    """``launcher``, or the ``<process>`` a child runs (it calls itself ``coco:<process>``)."""
    if pid == launcher:
        return "launcher"
    try:
        comm = Path(f"/proc/{pid}/comm").read_text().strip()
    except OSError:
        return str(pid)
    return comm.removeprefix("coco:")


def children(pid: int) -> list[int]:
    try:
        return [int(word) for word in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def in_workspace(*command: str) -> list[str]:
    """``command`` run as a user runs it: after ``source install/setup.bash`` (the installed scripts
    find their packages through it), replaced by the command itself (its pid is the launcher's)."""
    return ["bash", "-c", f'source "{INSTALL}/setup.bash" && exec "$@"', "bash", *command]


def soak(bag: Path, output: Path, minutes: float, display: bool, rate: float, every: float) -> dict[str, Trace]:
    command = in_workspace(str(INSTALL / "coco_core" / "lib" / "coco_core" / "coco-launch"), str(APP),
                           f"bag:={bag}", f"output:={output}", "loop:=true", f"display:={str(display).lower()}",
                           f"rate:={rate}", "--duration", str(minutes * 60))
    launcher = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                start_new_session=True)
    traces: dict[int, Trace] = {}
    begun = time.monotonic()
    try:
        while launcher.poll() is None:
            now = time.monotonic() - begun
            for pid in [launcher.pid, *children(launcher.pid)]:
                sample = rss(pid)
                if sample is None:
                    continue
                trace = traces.setdefault(pid, Trace(process_name(pid, launcher.pid)))
                trace.times.append(now)
                trace.anon_mb.append(sample[0])
                trace.shmem_mb.append(sample[1])
            done = now / (minutes * 60)
            sizes = ", ".join(f"{t.name} {t.anon_mb[-1] + t.shmem_mb[-1]:.0f} MB" for t in traces.values() if t.times)
            print(f"\r  {min(done, 1.0):5.1%} of {minutes:g} min: {sizes}", end="", flush=True)
            time.sleep(every)
    except KeyboardInterrupt:
        os.killpg(launcher.pid, signal.SIGINT)
        raise
    finally:
        print()
        _, errors = launcher.communicate(timeout=60)
    if launcher.returncode != 0:
        sys.exit(f"the application exited with {launcher.returncode}:\n{errors[-3000:]}")
    return {trace.name: trace for trace in traces.values()}


def table(traces: dict[str, Trace], limit: float, minutes: float) -> tuple[Table, dict[str, object]]:
    t = Table(f"RSS growth over a {minutes:g} min looped replay (after the first {WARM_UP:.0%})",
              ["process", "memory", "start MB", "end MB", "trend MB/min", f"goal <= {limit:g} MB/min"])
    t.add("issue 23 (anchor)", "RSS", "-", "-", f"{ANCHOR_MB_PER_MIN:.1f}", "-")
    results: dict[str, object] = {"anchor_mb_per_min": ANCHOR_MB_PER_MIN, "limit_mb_per_min": limit}
    for trace in traces.values():
        start = int(len(trace.times) * WARM_UP)
        for kind, values in (("anonymous", trace.anon_mb), ("shared memory", trace.shmem_mb)):
            slope = trace.slope(values)
            ok = bool(slope <= limit) if slope == slope else None
            t.add(trace.name, kind, f"{values[start]:.1f}", f"{values[-1]:.1f}", f"{slope:+.2f}", verdict(ok))
            results[f"{trace.name} {kind}"] = {"slope_mb_per_min": slope, "start_mb": values[start],
                                               "end_mb": values[-1], "goal_met": ok,
                                               "times_s": trace.times, "mb": values}
    t.notes.append("RssAnon and RssShmem of /proc/PID/status; shared memory counts in every process that maps it")
    return t, results


def draw(traces: dict[str, Trace]):  # type: ignore[no-untyped-def]
    def figure(plt):  # type: ignore[no-untyped-def]
        fig, ax = plt.subplots(figsize=(8, 4))
        for trace in traces.values():
            minutes = np.array(trace.times) / 60
            ax.plot(minutes, np.array(trace.anon_mb) + np.array(trace.shmem_mb), label=f"{trace.name}")
        ax.set_xlabel("minutes")
        ax.set_ylabel("RSS (MB)")
        ax.set_title("Baxter replay looped: RSS of each process")
        ax.legend()
        ax.grid(alpha=0.3)
        return fig
    return figure


def main() -> int:
    p = _report.parser("soak_memory", __doc__.splitlines()[0])
    p.add_argument("--minutes", type=float, default=10.0, help="how long the app runs (default 10)")
    p.add_argument("--display", choices=("true", "false"), default="true", help="the view process (default true)")
    p.add_argument("--rate", type=float, default=1.0, help="replay speed; 0: as fast as it goes (default 1)")
    p.add_argument("--every", type=float, default=5.0, help="seconds between samples (default 5)")
    p.add_argument("--limit", type=float, default=1.0, help="largest trend accepted, MB a minute (default 1)")
    p.add_argument("--bag", type=Path, help="a bag folder to loop (default: a generated 12 s Baxter session)")
    args = p.parse_args()
    with tempfile.TemporaryDirectory(prefix="soak_memory.") as folder:
        bag = args.bag
        if bag is None:
            bag = Path(folder) / "session"
            print("generating a 12 s Baxter session ...", flush=True)
            subprocess.run(in_workspace(str(INSTALL / "coco_ros" / "lib" / "coco_ros" / "baxter-session"), str(bag),
                                        "--quiet"), check=True)
        traces = soak(bag, Path(folder) / "out", args.minutes, args.display == "true", args.rate, args.every)
    t, results = table(traces, args.limit, args.minutes)
    _report.emit("soak_memory", args, [t], results)
    _report.save_plot(args, draw(traces))
    grown = [name for name, result in results.items()
             if isinstance(result, dict) and result.get("goal_met") is False]
    if grown:
        print(f"linear growth above {args.limit:g} MB/min: {', '.join(grown)}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
