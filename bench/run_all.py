"""Run every benchmark, each in its own process, and collect their JSON (and markdown for the docs).

    PYTHONPATH=coco_core .venv/bin/python bench/run_all.py                 # full run, about 6 min
    PYTHONPATH=coco_core .venv/bin/python bench/run_all.py --seconds 2     # quick run
    PYTHONPATH=coco_core .venv/bin/python bench/run_all.py --markdown /tmp/tables.md

``bench_replay`` and ``bench_latency`` start the installed ROS launcher and ``coco-replay``, and
``bench_palpation`` (about 7 minutes), ``bench_flowvr``, ``bench_hosts`` and ``bench_transforms_server`` the installed ``coco-launch``: build the workspace and
``source install/setup.bash`` first.

Each benchmark runs in a fresh interpreter so that one's threads, DDS participants and garbage do
not weigh on the next. Results go to ``bench/results/<name>.json``, plots to ``docs/img/<name>.png``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from _report import BENCH_DIR, IMG_DIR, REPO
from _table import Table

BENCHMARKS = ["bench_ports", "bench_pool", "bench_period", "bench_transforms", "bench_bag", "bench_replay",
              "bench_latency", "bench_hosting", "bench_display", "bench_check", "bench_processes", "bench_ipc", "bench_ipc_path", "bench_flowvr", "bench_hosts", "bench_haptics",
              "bench_vision", "bench_palpation", "bench_transforms_server"]


def markdown(results: Path) -> str:
    """Every table of the JSON files in ``results``, as markdown, with the machine line of each run."""
    parts = []
    for name in BENCHMARKS:
        path = results / f"{name}.json"
        if not path.exists():
            continue
        document = json.loads(path.read_text())
        m = document["machine"]
        parts.append(f"<!-- {name}: {m['date']}, Python {m['python']}, {m['cpus']} cpus, "
                     f"load {m.get('loadavg_1m', '?')}, rmw {m.get('rmw', '?')} -->")
        parts += [Table.from_json(t).markdown() + "\n" for t in document["tables"]]
    return "\n".join(parts)


def main() -> int:
    p = argparse.ArgumentParser(prog="bench/run_all.py", description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=10.0, help="seconds per condition of bench_period (default 10)")
    p.add_argument("--results", default=str(BENCH_DIR / "results"), help="folder for the JSON files")
    p.add_argument("--no-plot", action="store_true", help="draw no PNG")
    p.add_argument("--markdown", metavar="PATH", help="also write every table as markdown to PATH")
    p.add_argument("--only", choices=BENCHMARKS, action="append", help="run only this benchmark (repeatable)")
    args = p.parse_args()

    results = Path(args.results)
    env_path = str(REPO / "coco_core")
    failed = []
    started = time.monotonic()
    for name in args.only or BENCHMARKS:
        command = [sys.executable, str(BENCH_DIR / f"{name}.py"), "--json", str(results / f"{name}.json"),
                   "--plot", str(IMG_DIR / f"{name}.png")]
        if args.no_plot:
            command.append("--no-plot")
        if name == "bench_period":
            command += ["--seconds", str(args.seconds)]
        print(f"\n### {name}", flush=True)
        t0 = time.monotonic()
        env = dict(os.environ)
        env["PYTHONPATH"] = env_path + (":" + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        code = subprocess.call(command, env=env)
        print(f"### {name}: {'ok' if code == 0 else f'FAILED (exit {code})'} in {time.monotonic() - t0:.0f} s",
              flush=True)
        if code:
            failed.append(name)
    summary = f"all benchmarks: {time.monotonic() - started:.0f} s"
    print("\n" + summary + (f"; failed: {', '.join(failed)}" if failed else ""))
    if args.markdown:
        Path(args.markdown).write_text(markdown(results))
        print(f"wrote {args.markdown}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
