"""The transformation server under a flood (issue 36): the 5 ms Baxter replay's period error with
500 concurrent GETs on ``--transforms-server``, against the same replay with no request.

Each launch is a real ``coco-launch config/baxter_teleop_replay.xml display:=false
--transforms-server 0 --profile`` on the generated Baxter session (``out/baxter_session``, made by
the installed ``baxter-session`` on first use); the replay's activity (periodic, 5 ms) reports its
period error p50/p99/max in the final profile. In the *flood* launches a client process of its own
sends waves of 500 concurrent GETs over loopback (``/api/graph`` and ``/api/lookup`` in turn, one
connection each, all opened at once from one asyncio loop), a wave every ``--every`` seconds while
the replay runs; the *quiet* launches serve no request, and are the anchor. The two kinds of launch
alternate, ``--rounds`` of each.

Goal: no stall over 20 ms under the flood, i.e. the replay's largest period error with the flood at
most 20 ms; printed beside the quiet launches' largest, since a shared machine stalls a quiet replay
too (the figure then reads as the flood's share of it).

    source install/setup.bash && .venv/bin/python bench/bench_transforms_server.py [--rounds 3] [--no-plot]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import re
import statistics
import subprocess
import sys
from typing import Any
from urllib.parse import urlsplit

import _report
from _table import Table, fmt_ratio, fmt_time_ns, verdict

CLIENTS = 500
"""Concurrent GETs in one wave."""
GOAL_MS = 20.0
"""The largest period error of the replay under the flood, at most (ms)."""
PATHS = ("/api/graph", "/api/lookup?target=base&source=left_gripper")
SESSION = _report.REPO / "out" / "baxter_session"
LAUNCH = _report.REPO / "install" / "coco_core" / "lib" / "coco_core" / "coco-launch"
PROFILE_ROW = re.compile(r"^replay\s+periodic 5 ms\s+(\d+)\s+(\d+)\s+([\d.]+) / ([\d.]+) / ([\d.]+)\s*$", re.M)


def flood(url: str, every: float) -> None:
    """The client process: waves of :data:`CLIENTS` concurrent GETs every ``every`` seconds until
    stdin closes; prints ``answered failed`` at the end. One asyncio loop opens the connections, so
    that the client's own CPU time stays small beside the server's (500 threads of a client took a
    shared machine's cores from the replay as much as the server did)."""
    address = urlsplit(url)
    answered = failed = 0
    reasons: dict[str, int] = {}

    async def one(path: str) -> bool:
        reader, writer = await asyncio.open_connection(address.hostname, address.port)
        writer.write(f"GET {path} HTTP/1.1\r\nHost: {address.netloc}\r\nConnection: close\r\n\r\n".encode())
        await writer.drain()
        answer = await asyncio.wait_for(reader.read(), 30)
        writer.close()
        return answer.startswith(b"HTTP/1.1 200 ")

    async def waves() -> None:
        nonlocal answered, failed
        done = asyncio.get_running_loop().run_in_executor(None, sys.stdin.read)
        while not done.done():
            for result in await asyncio.gather(*(one(PATHS[i % len(PATHS)]) for i in range(CLIENTS)),
                                               return_exceptions=True):
                if result is True:
                    answered += 1
                else:
                    failed += 1
                    reason = type(result).__name__ if isinstance(result, BaseException) else "not 200"
                    reasons[reason] = reasons.get(reason, 0) + 1
            await asyncio.wait([done], timeout=every)

    asyncio.run(waves())
    print(answered, failed, json.dumps(reasons), flush=True)


def launch(flooded: bool, every: float) -> dict[str, Any]:
    """One replay launch: the replay's period error (us) and, when ``flooded``, the GETs answered."""
    command = [str(LAUNCH), "config/baxter_teleop_replay.xml", "display:=false", f"bag:={SESSION}",
               "output:=/tmp/bench_transforms_server", "--transforms-server", "0", "--profile", "1000"]
    launcher = subprocess.Popen(command, cwd=_report.REPO, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                text=True)
    assert launcher.stdout is not None
    url = ""
    while not url:
        line = launcher.stdout.readline()
        if not line:
            raise SystemExit(f"coco-launch ended before serving the graph (exit {launcher.wait()})")
        url = line.split("served at ", 1)[1].strip() if "served at " in line else ""
    client = None
    if flooded:
        client = subprocess.Popen([sys.executable, __file__, "--flood", url, "--every", str(every)],
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    out = launcher.stdout.read()
    if launcher.wait() != 0:
        raise SystemExit(f"coco-launch exited with {launcher.returncode}:\n{out}")
    figures: dict[str, Any] = {}
    if client is not None:
        answered, failed, reasons = client.communicate(timeout=120)[0].split(maxsplit=2)
        figures.update(answered=int(answered), failed=int(failed), failures=json.loads(reasons))
    row = PROFILE_ROW.search(out)
    if row is None:
        raise SystemExit(f"no replay row in the profile:\n{out}")
    cycles, overruns, p50, p99, largest = row.groups()
    figures.update(cycles=int(cycles), overruns=int(overruns), p50_us=float(p50), p99_us=float(p99),
                   max_us=float(largest))
    return figures


def main() -> None:
    parser = _report.parser("bench_transforms_server", __doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3, help="launches of each kind, alternating (default 3)")
    parser.add_argument("--every", type=float, default=1.0, help="seconds between two waves of GETs (default 1)")
    parser.add_argument("--flood", metavar="URL", help=argparse.SUPPRESS)  # the client process's mode
    args = parser.parse_args()
    if args.flood:
        flood(args.flood, args.every)
        return
    if not (SESSION / "metadata.yaml").exists():
        subprocess.run([str(_report.REPO / "install" / "coco_ros" / "lib" / "coco_ros" / "baxter-session"),
                        str(SESSION)], check=True, capture_output=True)
    load = os.getloadavg()[0]
    rounds: list[dict[str, dict[str, Any]]] = []
    for index in range(args.rounds):
        rounds.append({"quiet": launch(False, args.every), "flood": launch(True, args.every)})
        print(f"round {index + 1}: {rounds[-1]}", flush=True)

    def med(kind: str, key: str) -> float:
        return statistics.median(r[kind][key] for r in rounds)

    def worst(kind: str) -> float:
        return max(r[kind]["max_us"] for r in rounds)

    ok = worst("flood") <= GOAL_MS * 1e3
    table = Table(f"The 5 ms Baxter replay's period error, {CLIENTS} concurrent GETs on the transformation server "
                  f"(medians of {args.rounds} launches)",
                  ["launch", "p50", "p99", "max (median)", "max (worst)", "GETs answered / failed",
                   "p99 / quiet", "goal"])
    table.add("quiet (anchor)", fmt_time_ns(med("quiet", "p50_us") * 1e3), fmt_time_ns(med("quiet", "p99_us") * 1e3),
              fmt_time_ns(med("quiet", "max_us") * 1e3), fmt_time_ns(worst("quiet") * 1e3), "-", "1.00x", "-")
    table.add("flood", fmt_time_ns(med("flood", "p50_us") * 1e3), fmt_time_ns(med("flood", "p99_us") * 1e3),
              fmt_time_ns(med("flood", "max_us") * 1e3), fmt_time_ns(worst("flood") * 1e3),
              f"{sum(r['flood']['answered'] for r in rounds)} / {sum(r['flood']['failed'] for r in rounds)}",
              fmt_ratio(statistics.median(r["flood"]["p99_us"] / r["quiet"]["p99_us"] for r in rounds)),
              f"max <= {GOAL_MS:g} ms: {verdict(ok)}")
    table.notes.append(f"period error: |start of a cycle - its deadline| of the replay's activity, from the launcher's "
                       f"profile over the whole 12 s replay; a wave of {CLIENTS} GETs every {args.every:g} s "
                       f"({' and '.join(PATHS)} in turn), from a client process of its own, over loopback.")
    table.notes.append(f"load average before the run: {load:.2f} on {os.cpu_count()} cores (a shared machine stalls "
                       "the quiet replay too: compare the two rows).")
    _report.emit("bench_transforms_server", args, [table], {"rounds": rounds, "goal_ok": ok})

    def draw(plt: Any) -> Any:
        figure, axes = plt.subplots(figsize=(7, 3))
        for offset, kind in ((-0.2, "quiet"), (0.2, "flood")):
            axes.bar([i + offset for i in range(len(rounds))], [r[kind]["max_us"] / 1e3 for r in rounds], 0.4,
                     label=kind)
        axes.axhline(GOAL_MS, color="grey", linestyle="--", label=f"goal ({GOAL_MS:g} ms)")
        axes.set_xlabel("round")
        axes.set_ylabel("largest period error (ms)")
        axes.set_title(f"5 ms replay, {CLIENTS} concurrent GETs")
        axes.legend()
        figure.tight_layout()
        return figure

    _report.save_plot(args, draw)


if __name__ == "__main__":
    main()
