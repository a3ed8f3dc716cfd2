"""A connection between two hosts (issue 21) across a simulated network link, against a plain rclpy
publisher/subscriber pair on the same link and the same connection between two processes of one host.

The hosts ``robot`` and ``graphics`` are network namespaces of this machine joined by a kernel link
(veth pairs on a bridge, MTU 1500, no impairment: ``test/netns.py``); DDS between them is real UDP
(Fast DDS's UDPv4 transport, discovery over the subnet). Variants, each a run of its own:

- *rclpy pair, two hosts* (the anchor): ``bench/_hosts_rclpy.py``, a publisher in ``robot``, a
  subscriber in ``graphics``; small samples as ``sensor_msgs/JointState`` (19 positions), frames as
  two raw ``sensor_msgs/Image`` (rgb8 colour, 16UC1 depth), reliable, keep last N;
- *CoCo, two hosts*: the bench application (``bench/_hosts_components.py``: Source -> Sink, a
  ``BUFFER`` connection of N) with the source in ``<host name="robot">`` and the sink in
  ``<host name="graphics">``, ``coco-launch app.xml --host NAME`` in each namespace; frames through
  the connection's ``codec="rgbd"`` (JPEG colour, Zstandard depth);
- *CoCo, two processes, one host*: the same application with the source in a ``<process>`` of its
  own (the shared-memory channel), one ``coco-launch`` in ``robot``.

Payloads: a small sample (19 float64) and a 640x480 RGB-D frame (a real Redwood frame); the frames
twice, on the bare veth pairs (memory speed) and on the link limited to 1 Gbit/s (``tc tbf``: a
gigabit Ethernet between two computers, where a codec pays). Each run has
two phases: *latency*, one sample per period (small: 100 Hz, frames: 30 Hz; the first tenth left
out), the time from the write (carried in the payload) to the sink's update (p50, p99); then
*burst*, N samples written back to back: throughput = samples received / (last arrival - first
write). Goals: the connection between hosts within 1.1x of the rclpy pair for small samples
(latency p50, throughput), better than it for frames (the codec). Variants run in interleaved
rounds; ratios are medians of per-round ratios, the verdicts are judged on them.

    source install/setup.bash && .venv/bin/python bench/bench_hosts.py [--rounds 1] [--json PATH] [--no-plot]
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import _report
from _table import Table, fmt_ratio, fmt_time_ns, verdict

import numpy as np

from coco_core.hosts.key import write_key

BENCH = Path(__file__).resolve().parent
sys.path.insert(0, str(_report.REPO / "test"))
from netns import Network, unavailable  # noqa: E402  (test/ is on the path only now)

DOMAIN = 179
ANCHOR = "rclpy pair, two hosts"
HOSTS = "CoCo, two hosts"
PROCESSES = "CoCo, two processes, one host"
ENCODED = "rclpy pair, CoCo's Sample encoding"
"""``--split``: the anchor's pair sending CoCo's own Sample of the small value (``_hosts_rclpy.py``)."""
VARIANTS = [ANCHOR, HOSTS, PROCESSES]
SMALL = {"kind": "small", "latency": 300, "burst": 1000, "period": 0.01, "goal": 1.1}
FRAME = {"kind": "frame", "latency": 60, "burst": 20, "period": 1 / 30, "goal": 1.0}
GIGABIT = 1000.0
CASES: dict[str, dict[str, Any]] = {
    "small sample (19 float64), veth": {**SMALL, "rate": None, "variants": VARIANTS},
    "RGB-D frame 640x480, veth": {**FRAME, "rate": None, "variants": VARIANTS},
    "RGB-D frame 640x480, 1 Gbit/s": {**FRAME, "rate": GIGABIT, "variants": [ANCHOR, HOSTS]},
}
"""Per case: samples of the latency phase and of the burst, the latency phase's period, the link's rate
limit (None: the bare veth pairs, which move data at memory speed; 1 Gbit/s: a gigabit Ethernet
between the robot's and the graphics computer, ``tc tbf``), the variants (two processes of one host
use no link), and the goal: the connection between hosts at most ``goal`` times the anchor's latency
p50 and at least 1/``goal`` its throughput (frames, ``goal`` 1: strictly better)."""
RUN_TIMEOUT_S = 90.0
GRACE_S = 15.0

APP = """<package name="bench_hosts">
  <components>
    <component><name>source</name><task>_hosts_components:Source</task>
      <attributes><attribute name="kind" value="{kind}"/><attribute name="latency" value="{latency}"/>
        <attribute name="burst" value="{burst}"/></attributes></component>
    <component><name>sink</name><task>_hosts_components:Sink</task>
      <attributes><attribute name="path" value="{record}"/><attribute name="last" value="{last}"/></attributes>
    </component>
  </components>
  <connections>
    <connection data="BUFFER" buffersize="{burst}"{codec}><src task="source" port="out"/><dest task="sink" port="sample"/></connection>
  </connections>
  <activities>
    {open_source}<activity name="produce"><schedule type="periodic" period="{period_ms}"/>
      <components><component name="source"/></components></activity>{close_source}
    {open_sink}<activity name="consume"><schedule type="triggered"/>
      <components><component name="sink"/></components></activity>{close_sink}
  </activities>
</package>
"""


def application(variant: str, payload: dict[str, Any], record: Path) -> str:
    if variant == HOSTS:
        wraps = ('<host name="robot">', "</host>", '<host name="graphics">', "</host>")
    else:
        wraps = ('<process name="producing">', "</process>", "", "")
    return APP.format(kind=payload["kind"], latency=payload["latency"], burst=payload["burst"], record=record,
                      last=payload["latency"] + payload["burst"] - 1, period_ms=payload["period"] * 1e3,
                      codec=' codec="rgbd"' if payload["kind"] == "frame" else "",
                      open_source=wraps[0], close_source=wraps[1], open_sink=wraps[2], close_sink=wraps[3])


def environment() -> dict[str, str]:
    """This environment with the bench folder importable by the launchers and their children."""
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(BENCH), os.environ.get("PYTHONPATH", "")]),
            "PYTHONUNBUFFERED": "1"}


class Failed(Exception):
    """A variant could not run (its reason goes into the table)."""


def finish(processes: dict[str, subprocess.Popen[str]], logs: dict[str, Path], deadline: float) -> None:
    """Wait for every process until ``deadline``. Once one has ended, the others get ``GRACE_S`` to
    end by themselves (a subscriber still taking what was acknowledged, a host stopped by the other's
    stop), then SIGINT (as a user would); any non-zero exit is a failure, told with its output."""
    import signal

    interrupted: set[str] = set()
    grace: float | None = None
    while any(p.poll() is None for p in processes.values()) and time.monotonic() < deadline:
        if grace is None and any(p.poll() is not None for p in processes.values()):
            grace = time.monotonic() + GRACE_S
        if grace is not None and time.monotonic() > grace and not interrupted:
            for name, process in processes.items():
                if process.poll() is None:
                    process.send_signal(signal.SIGINT)
                    interrupted.add(name)
            deadline = min(deadline, time.monotonic() + 10)
        time.sleep(0.05)
    late = [name for name, p in processes.items() if p.poll() is None]
    for name in late:
        processes[name].kill()
        processes[name].wait()
    outputs = {name: logs[name].read_text(errors="replace") for name in processes}
    if late:
        raise Failed(f"{', '.join(late)} still running after {RUN_TIMEOUT_S:.0f} s:\n" +
                     "\n".join(f"--- {n}:\n{outputs[n][-2000:]}" for n in late))
    bad = {name: p.returncode for name, p in processes.items() if p.returncode != 0}
    if bad:
        name = min(bad, key=lambda n: n in interrupted)  # the one that failed first, not the one stopped then
        raise Failed(f"{name} exited with {bad[name]}: {outputs[name].strip()[-1500:]}")


def run(net: Network, variant: str, payload: dict[str, Any], folder: Path) -> list[list[float]]:
    """One run of ``variant``: the sink's records (number, phase, written, received)."""
    tag = time.monotonic_ns()
    record = folder / f"record-{tag}.json"
    deadline = time.monotonic() + RUN_TIMEOUT_S
    processes: dict[str, subprocess.Popen[str]] = {}
    logs: dict[str, Path] = {}

    def start(name: str, host: str, argv: list[str]) -> None:
        logs[name] = folder / f"{name}-{tag}.log"
        with logs[name].open("w") as log:  # a file, not a pipe: a long output never blocks the process
            processes[name] = net[host].popen(argv, stdout=log, stderr=subprocess.STDOUT, text=True,
                                              env=environment(), cwd=str(_report.REPO))

    if variant in (ANCHOR, ENCODED):
        script = str(BENCH / "_hosts_rclpy.py")
        kind = "sample" if variant == ENCODED else payload["kind"]
        counts = [kind, str(payload["latency"]), str(payload["burst"])]
        start("subscriber", "graphics", [sys.executable, script, "sub", *counts, str(record)])
        while "ready" not in logs["subscriber"].read_text() and processes["subscriber"].poll() is None:
            if time.monotonic() > deadline:
                break
            time.sleep(0.01)
        start("publisher", "robot", [sys.executable, script, "pub", *counts, str(payload["period"])])
    else:
        path = folder / f"{variant.split(',')[1].strip().replace(' ', '_')}.xml"
        path.write_text(application(variant, payload, record))
        launch = [sys.executable, "-m", "coco_core.launcher", str(path)]
        if variant == HOSTS:
            key = folder / "app.key"
            if not key.exists():
                write_key(str(key))
            for host in ("graphics", "robot"):
                start(host, host, [*launch, "--host", host, "--key", str(key)])
        else:
            start("launcher", "robot", launch)
    finish(processes, logs, deadline)
    if not record.exists():
        raise Failed("the sink wrote no record")
    records: list[list[float]] = json.loads(record.read_text())
    return records


def figures(records: list[list[float]], payload: dict[str, Any]) -> dict[str, float]:
    """Latency p50/p99 of the latency phase (its first tenth left out) and the burst's throughput."""
    latency = [r for r in records if r[1] == 0 and r[0] >= payload["latency"] // 10]
    burst = [r for r in records if r[1] == 1]
    age = np.array([received - written for _, _, written, received in latency])
    out = {"received": float(len(records)), "expected": float(payload["latency"] + payload["burst"]),
           "p50": float(np.percentile(age, 50)) if age.size else float("nan"),
           "p99": float(np.percentile(age, 99)) if age.size else float("nan"), "throughput": float("nan")}
    if len(burst) > 1:
        out["throughput"] = len(burst) / (max(r[3] for r in burst) - min(r[2] for r in burst))
    return out


def draw(plt: Any, rounds: dict[str, list[dict[str, dict[str, float]]]], cases: dict[str, dict[str, Any]]) -> Any:
    """Per case: latency p50/p99 and burst throughput of each variant (medians over the rounds), the
    value written on each bar (the variants differ by up to 40x: a linear axis with its numbers)."""
    def median(case: str, variant: str, key: str) -> float:
        values = [r[variant][key] for r in rounds[case] if variant in r]
        return statistics.median(values) if values else float("nan")

    figure, axes = plt.subplots(1, 2 * len(cases), figsize=(6 * len(cases), 3.6), squeeze=False)
    axes = axes[0]
    colors = {ANCHOR: "#4c72b0", HOSTS: "#dd8452", PROCESSES: "#55a868", ENCODED: "#8172b2"}
    for column, (case, payload) in enumerate(cases.items()):
        left, right = axes[2 * column], axes[2 * column + 1]
        variants = payload["variants"]
        y = np.arange(len(variants))
        for offset, key, color in ((-0.2, "p50", "#4c72b0"), (0.2, "p99", "#dd8452")):
            values = [median(case, v, key) * 1e3 for v in variants]
            left.barh(y + offset, values, 0.4, label=key, color=color)
            for row, value in zip(y, values):
                left.text(value, row + offset, f" {value:.3g}", va="center", fontsize=6)
        left.set_yticks(y, [v.replace(", ", ",\n") for v in variants], fontsize=7)
        left.set_xlabel("latency (ms)")
        left.set_title(case, fontsize=8)
        left.legend(fontsize=7)
        rates = [median(case, v, "throughput") for v in variants]
        right.barh(y, rates, color=[colors[v] for v in variants])
        for row, rate in zip(y, rates):
            right.text(rate, row, f" {rate:,.0f}", va="center", fontsize=7)
        right.set_yticks(y, [""] * len(variants))
        right.set_xlabel("burst throughput (samples/s)")
        right.set_title("throughput", fontsize=8)
    figure.tight_layout()
    return figure


def main() -> None:
    parser = _report.parser("bench_hosts", __doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2, help="interleaved rounds of every variant (default 2)")
    parser.add_argument("--cases", nargs="+", metavar="WORD", help="only the cases whose name has one of these "
                        f"words ({'; '.join(CASES)})")
    parser.add_argument("--split", action="store_true",
                        help=f"small samples: also the variant '{ENCODED}' (what the encoding costs)")
    args = parser.parse_args()
    cases = {name: dict(case) for name, case in CASES.items()
             if not args.cases or any(word in name for word in args.cases)}
    if not cases:
        raise SystemExit(f"no case has any of {args.cases}; cases: {'; '.join(CASES)}")
    if args.split:
        for case in cases.values():
            if case["kind"] == "small":
                case["variants"] = [*case["variants"], ENCODED]
    reason = unavailable()
    if reason:
        raise SystemExit(f"bench_hosts needs simulated hosts: {reason}")
    load = os.getloadavg()[0]
    rounds: dict[str, list[dict[str, dict[str, float]]]] = {name: [] for name in cases}
    failures: dict[tuple[str, str], str] = {}
    """(payload, variant) -> why it could not run (it is not tried again in later rounds)."""
    with tempfile.TemporaryDirectory(prefix="bench_hosts") as name, Network(["robot", "graphics"], DOMAIN) as net:
        folder = Path(name)
        for index in range(args.rounds):
            for payload_name, payload in cases.items():
                net.limit(payload["rate"])
                round_: dict[str, dict[str, float]] = {}
                variants = payload["variants"]
                for variant in variants[index % len(variants):] + variants[:index % len(variants)]:
                    if (payload_name, variant) in failures:
                        continue
                    started = time.monotonic()
                    try:
                        round_[variant] = figures(run(net, variant, payload, folder), payload)
                    except Failed as error:
                        failures[payload_name, variant] = str(error)
                        print(f"{payload_name}, {variant}: did not run: {error}", flush=True)
                        continue
                    print(f"round {index + 1}, {payload_name}, {variant}: {round_[variant]} "
                          f"({time.monotonic() - started:.1f} s)", flush=True)
                rounds[payload_name].append(round_)

    def median(payload: str, variant: str, key: str) -> float:
        values = [r[variant][key] for r in rounds[payload] if variant in r]
        return statistics.median(values) if values else float("nan")

    def ratio(payload: str, variant: str, key: str) -> float:
        """Median over rounds of variant / anchor (throughput: higher is better, latency: lower)."""
        values = [r[variant][key] / r[ANCHOR][key] for r in rounds[payload] if variant in r and ANCHOR in r]
        return statistics.median(values) if values else float("nan")

    table = Table(f"Across a network link between two hosts (network namespaces, veth pairs on a bridge): medians "
                  f"of {args.rounds} round(s)",
                  ["payload, link", "variant", "received", "latency p50", "p50 / rclpy", "latency p99", "p99 / rclpy",
                   "throughput", "throughput / rclpy", "goal"])
    verdicts: dict[str, Any] = {}
    for payload_name, payload in cases.items():
        for variant in payload["variants"]:
            if not any(variant in r for r in rounds[payload_name]):
                table.add(payload_name, variant, "-", "n/a", "-", "n/a", "-", "n/a", "-", "did not run")
                continue
            p50, p99, rate = (ratio(payload_name, variant, k) for k in ("p50", "p99", "throughput"))
            goal = "-"
            if variant == HOSTS:
                limit = payload["goal"]
                if limit > 1:
                    ok_latency, ok_rate = p50 <= limit, rate >= 1 / limit
                    words = f"p50 <= {limit:g}x: {verdict(ok_latency)}; throughput >= 1/{limit:g}x: {verdict(ok_rate)}"
                else:
                    ok_latency, ok_rate = p50 < 1, rate > 1
                    words = f"p50 < rclpy: {verdict(ok_latency)}; throughput > rclpy: {verdict(ok_rate)}"
                goal = words
                verdicts[payload_name] = {"p50_ratio": p50, "throughput_ratio": rate, "latency_ok": ok_latency,
                                          "throughput_ok": ok_rate}
            anchor = variant == ANCHOR
            received = f"{median(payload_name, variant, 'received'):.0f}/{payload['latency'] + payload['burst']}"
            table.add(payload_name, variant, received, fmt_time_ns(median(payload_name, variant, "p50") * 1e9),
                      "1.00x" if anchor else fmt_ratio(p50), fmt_time_ns(median(payload_name, variant, "p99") * 1e9),
                      "1.00x" if anchor else fmt_ratio(p99), f"{median(payload_name, variant, 'throughput'):,.0f}/s",
                      "1.00x" if anchor else fmt_ratio(rate), goal)
    table.notes.append("latency: the payload's write time (carried in it) -> the reader's callback / update, "
                       "latency phase only (small: 100 Hz, frames: 30 Hz, the first tenth left out); throughput: "
                       "the burst's samples received / (last arrival - first write)")
    table.notes.append("ratios: variant / rclpy, medians of per-round ratios (latency: lower is better; "
                       "throughput: higher is better); p99 is shown, not judged (a 2-core shared machine)")
    table.notes.append("frames: the rclpy pair sends raw sensor_msgs/Image (rgb8 + 16UC1, 1.5 MB); CoCo between "
                       "hosts the connection's codec=\"rgbd\" (JPEG colour, Zstandard depth); between processes "
                       "the shared-memory channel (no codec)")
    table.notes.append("veth: the bare veth pairs, at memory speed; 1 Gbit/s: what each host sends limited by a token "
                       "bucket on its eth0 (tc tbf, 1 ms burst), as a gigabit network card")
    if args.split:
        table.notes.append(f"{ENCODED}: the rclpy pair sending the small value as a coco_interfaces/Sample made by "
                           "CoCo's encoder, decoded by its decoder in the subscriber's callback (received: decoded); "
                           "the rest of CoCo two hosts' latency is its ports and threads")
    for (payload_name, variant), why in failures.items():
        table.notes.append(f"{variant}, {payload_name}: did not run: {why.splitlines()[0][:300]}")
    table.notes.append(f"load average before the run: {load:.2f} on {os.cpu_count()} cores")
    _report.emit("bench_hosts", args, [table], {"rounds": rounds, "verdicts": verdicts,
                                                "failures": {f"{p}, {v}": why for (p, v), why in failures.items()}})

    _report.save_plot(args, lambda plt: draw(plt, rounds, cases))


if __name__ == "__main__":
    main()
