"""What every benchmark script shares around its measurement: command line, machine facts, JSON, plots.

Plots are optional: without matplotlib a benchmark still prints its tables and writes its JSON, and
says that it made no picture.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Iterable, Iterator

from _table import Table

BENCH_DIR = Path(__file__).resolve().parent
REPO = BENCH_DIR.parent
IMG_DIR = REPO / "docs" / "img"

# Let `python bench/x.py` work without PYTHONPATH=coco_core, as the docs' command does.
if str(REPO / "coco_core") not in sys.path:
    sys.path.insert(0, str(REPO / "coco_core"))


def parser(name: str, description: str) -> argparse.ArgumentParser:
    """The options every benchmark takes: where the JSON and the plot go."""
    p = argparse.ArgumentParser(prog=f"bench/{name}.py", description=description)
    p.add_argument("--json", metavar="PATH", help="write the results as JSON to PATH")
    p.add_argument("--plot", metavar="PATH", default=str(IMG_DIR / f"{name}.png"),
                   help=f"PNG to draw (default: docs/img/{name}.png); needs matplotlib")
    p.add_argument("--no-plot", action="store_true", help="draw no PNG")
    return p


def machine() -> dict[str, Any]:
    """Facts a reader needs to compare two runs."""
    facts: dict[str, Any] = {
        "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        "python": platform.python_version(),
        "implementation": platform.python_implementation(),
        "platform": platform.platform(),
        "cpus": os.cpu_count(),
        "switchinterval_s": sys.getswitchinterval(),
    }
    try:
        facts["loadavg_1m"] = round(os.getloadavg()[0], 2)
    except OSError:
        pass
    if "rclpy" in sys.modules:
        from _ros import rmw_name
        facts["rmw"] = rmw_name()
    return facts


class LoadMeter:
    """``with LoadMeter() as m:`` -> ``m.others``: the share of all cores that *other* processes used;
    ``m.own``: the cores this process used (its CPU seconds over the wall time).

    Read from /proc/stat (every process, steal included) minus this process's own CPU time, so that a
    timing figure can be printed next to how busy the shared machine was meanwhile. ``children``:
    the processes this one waited for (a bench's launchers, and theirs) count as its own, in both
    figures. None off Linux.
    """

    def __init__(self, children: bool = False) -> None:
        self.children = children
        self.others: float | None = None
        self.own: float | None = None
        self._start: tuple[float, float, float] | None = None

    def _read(self) -> tuple[float, float, float] | None:
        try:
            fields = Path("/proc/stat").read_text().splitlines()[0].split()[1:]
        except OSError:
            return None
        ticks = [int(f) for f in fields]
        busy = sum(ticks) - ticks[3] - ticks[4] - sum(ticks[8:])  # minus idle, iowait, guest (counted in user)
        times = os.times()
        own = times.user + times.system
        if self.children:
            own += times.children_user + times.children_system
        return busy / os.sysconf("SC_CLK_TCK"), own, time.monotonic()

    def __enter__(self) -> LoadMeter:
        self._start = self._read()
        return self

    def __exit__(self, *exc: object) -> None:
        end = self._read()
        if self._start is None or end is None:
            return
        busy, own, wall = (e - s for e, s in zip(end, self._start))
        self.others = max(0.0, (busy - own) / (wall * (os.cpu_count() or 1)))
        self.own = own / wall


@contextlib.contextmanager
def other_processes(count: int) -> Iterator[None]:
    """``count`` other processes that spin on the CPU meanwhile: a shared machine, made reproducible."""
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(count)]
    try:
        yield
    finally:
        for spinner in spinners:
            spinner.kill()
            spinner.wait()


def emit(name: str, args: argparse.Namespace, tables: Iterable[Table], results: dict[str, Any]) -> None:
    """Print the tables and write the JSON file when asked."""
    tables = list(tables)
    for table in tables:
        print()
        print(table.text())
    print()
    if args.json:
        path = Path(args.json)
        path.parent.mkdir(parents=True, exist_ok=True)
        document = {"benchmark": name, "machine": machine(), "tables": [t.to_json() for t in tables],
                    "results": results}
        path.write_text(json.dumps(document, indent=1) + "\n")
        print(f"wrote {path}")


def pyplot() -> Any | None:
    """matplotlib.pyplot with a non-interactive backend, or None when matplotlib is missing."""
    try:
        import matplotlib
    except ImportError:
        return None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def save_plot(args: argparse.Namespace, draw: Any) -> None:
    """Call ``draw(plt) -> figure`` and save it to ``args.plot``, unless plots are off or impossible."""
    if args.no_plot:
        return
    plt = pyplot()
    if plt is None:
        print("matplotlib is not installed: no plot drawn")
        return
    figure = draw(plt)
    path = Path(args.plot)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(figure)
    print(f"wrote {path}")


def activity_profile(shots: Iterable[Any], process: str, activity: str) -> dict[str, float]:
    """The profile's figures of ``activity`` in ``process`` (``ProfileSnapshot`` objects, as the
    process level gathers them): cycles, overruns, and the period error p50/p99/max in microseconds."""
    row = next(row for shot in shots if shot.process == process for row in shot.activities if row[0] == activity)
    p50, p99, largest = (float(word) for word in row[4].split(" / "))
    return {"cycles": int(row[2]), "overruns": int(row[3]), "p50_us": p50, "p99_us": p99, "max_us": largest}
