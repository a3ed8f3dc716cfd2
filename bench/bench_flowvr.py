"""FlowVR's greedy coupling (issue 22): a 1 kHz producer and a 60 Hz consumer, against the same
coupling hand-written with a DATA connection, in one process and across two.

The producer (``CostlyProducer``, 0.1 ms of work) runs on a periodic 1 ms schedule; the consumer
(``CostlyConsumer``, 5 ms of work) on a periodic 16.7 ms one (60 Hz), each in its own activity. The
coupling between them is the only difference between the variants:

- *Greedy*: ``<filter type="Greedy"/>`` (the consumer gets the newest message written, or reuses
  the last one);
- *DATA*: the hand-written coupling, a plain DATA connection (the newest value only, read once);

each in one process and with the producer's activity in a ``<process>`` of its own (the filter then
on the consumer's side of the shared-memory channel, ``docs/flowvr.md``), plus the *producer
alone* (no consumer, no connection) as the anchor of the producer's timing. Every variant is a real
``coco-launch`` of a generated application file; both components record what they did from the
message stamps (which cross processes with the values) and write it to a file at their stop.

Figures: the *age* of the message the consumer gets (read time - the stamp's write time), p50 and
p99 over every read; the producer's *period error*, |interval between two writes - 1 ms|, p99.
Goals: the Greedy coupling no worse than the hand-written DATA connection (age p50 and p99), and the
producer's p99 period error within 1.2x of the producer alone. The variants run in interleaved
rounds; each ratio is the median of the per-round ratios (the verdict is judged on the printed one).

    .venv/bin/python bench/bench_flowvr.py [--rounds 3] [--values 90] [--json PATH] [--no-plot]
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import _report
from _table import Table, fmt_ratio, fmt_time_ns, verdict

import numpy as np

PRODUCER_PERIOD_MS = 1.0
CONSUMER_PERIOD_MS = 1000.0 / 60
GOAL_AGE = 1.0
"""Greedy's age / DATA's age at most this (no worse)."""
GOAL_PERIOD = 1.2
"""The producer's p99 period error coupled / alone at most this."""

APP = """<package name="bench_flowvr">
    <components>
        <component><name>producer</name><task>CostlyProducer</task><library>coco_core</library>
            <attributes><attribute name="cost_ms" value="0.1"/>
                <attribute name="record" value="{folder}/producer.json"/></attributes></component>
        {consumer}
    </components>
    <connections>{connection}</connections>
    <activities>
        {open}<activity name="produce"><schedule type="periodic" period="{producer_period}"/>
            <components><component name="producer"/></components></activity>{close}
        {consume}
    </activities>
</package>
"""
CONSUMER = """<component><name>consumer</name><task>CostlyConsumer</task><library>coco_core</library>
            <attributes><attribute name="cost_ms" value="5"/><attribute name="stop_after" value="{values}"/>
                <attribute name="record" value="{folder}/consumer.json"/></attributes></component>"""
CONSUME = """<activity name="consume"><schedule type="periodic" period="{consumer_period}"/>
            <components><component name="consumer"/></components></activity>"""
CONNECTIONS = {
    "Greedy": '<connection><src task="producer" port="out"/><dest task="consumer" port="item"/>'
              '<filter type="Greedy"/></connection>',
    "DATA": '<connection data="DATA"><src task="producer" port="out"/><dest task="consumer" port="item"/>'
            '</connection>',
}
VARIANTS = ["producer alone", "Greedy, one process", "DATA, one process", "Greedy, two processes",
            "DATA, two processes"]


def application(variant: str, folder: Path, values: int) -> str:
    alone = variant == "producer alone"
    apart = "two processes" in variant
    return APP.format(
        folder=folder, producer_period=PRODUCER_PERIOD_MS,
        consumer="" if alone else CONSUMER.format(values=values, folder=folder),
        connection="" if alone else CONNECTIONS[variant.split(",")[0]],
        open='<process name="producing">' if apart else "", close="</process>" if apart else "",
        consume="" if alone else CONSUME.format(consumer_period=CONSUMER_PERIOD_MS))


def run(variant: str, values: int) -> dict[str, Any]:
    """One launch of ``variant``: the figures of its records (seconds)."""
    from coco_core.demo.coupling import load_record

    with tempfile.TemporaryDirectory(prefix="bench_flowvr") as name:
        folder = Path(name)
        path = folder / "app.xml"
        path.write_text(application(variant, folder, values))
        seconds = values / 60.0
        command = [sys.executable, "-m", "coco_core.launcher", str(path)]
        if variant == "producer alone":
            command += ["--duration", f"{seconds:.2f}"]
        launched = subprocess.run(command, capture_output=True, text=True, timeout=120)
        if launched.returncode != 0:
            raise SystemExit(f"{variant}: coco-launch exited with {launched.returncode}:\n{launched.stderr}")
        producer = load_record(folder / "producer.json")
        stamped = np.array([write.stamped for write in producer.writes])
        skip = len(stamped) // 10  # the first tenth: both loops starting
        error = np.abs(np.diff(stamped[skip:]) - PRODUCER_PERIOD_MS / 1e3)
        figures = {"period_error_p99": float(np.percentile(error, 99)), "writes": len(stamped)}
        if variant != "producer alone":
            consumer = load_record(folder / "consumer.json")
            taken = consumer.taken[len(consumer.taken) // 10:]
            age = np.array([one.answered - one.stamped for one in taken])
            figures.update(age_p50=float(np.percentile(age, 50)), age_p99=float(np.percentile(age, 99)),
                           reads=len(age), reused=sum(not one.new for one in taken))
        return figures


def median_ratio(rounds: list[dict[str, dict[str, float]]], mine: str, anchor: str, key: str) -> float:
    """The median over the rounds of mine[key] / anchor[key]."""
    return statistics.median(r[mine][key] / r[anchor][key] for r in rounds)


def main() -> None:
    parser = _report.parser("bench_flowvr", __doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3, help="interleaved rounds of every variant (default 3)")
    parser.add_argument("--values", type=int, default=90,
                        help="values the consumer takes per launch (at 60 Hz; default 90: 1.5 s)")
    args = parser.parse_args()
    rounds: list[dict[str, dict[str, float]]] = []
    load = os.getloadavg()[0]
    for index in range(args.rounds):
        rounds.append({variant: run(variant, args.values) for variant in VARIANTS})
        print(f"round {index + 1}: {rounds[-1]}", flush=True)

    def med(variant: str, key: str) -> float:
        return statistics.median(r[variant][key] for r in rounds)

    table = Table(f"Greedy coupling, 1 kHz producer -> 60 Hz consumer (medians of {args.rounds} rounds)",
                  ["variant", "age p50", "age p99", "producer period error p99", "age p50 / DATA",
                   "age p99 / DATA", "period error p99 / alone", "goal"])
    table.add("producer alone", "-", "-", fmt_time_ns(med("producer alone", "period_error_p99") * 1e9), "-", "-",
              "1.00x", "-")
    verdicts: dict[str, dict[str, float | bool]] = {}
    for variant in VARIANTS[1:]:
        anchor = "DATA, " + variant.split(", ")[1]
        greedy = variant.startswith("Greedy")
        p50 = median_ratio(rounds, variant, anchor, "age_p50")
        p99 = median_ratio(rounds, variant, anchor, "age_p99")
        period = median_ratio(rounds, variant, "producer alone", "period_error_p99")
        ok_age = p50 <= GOAL_AGE and p99 <= GOAL_AGE
        ok_period = period <= GOAL_PERIOD
        goal = "-"
        if greedy:
            goal = (f"age <= {GOAL_AGE:g}x DATA: {verdict(ok_age)}; period <= {GOAL_PERIOD:g}x alone: "
                    f"{verdict(ok_period)}")
            verdicts[variant] = {"age_p50_ratio": p50, "age_p99_ratio": p99, "period_ratio": period,
                                 "age_ok": ok_age, "period_ok": ok_period}
        table.add(variant, fmt_time_ns(med(variant, "age_p50") * 1e9), fmt_time_ns(med(variant, "age_p99") * 1e9),
                  fmt_time_ns(med(variant, "period_error_p99") * 1e9), "-" if not greedy else fmt_ratio(p50),
                  "-" if not greedy else fmt_ratio(p99), fmt_ratio(period), goal)
    table.notes.append("age: the consumer's read time - the write time in the value's stamp (the stamp crosses "
                       "processes with the value); period error: |interval between two writes - 1 ms|; the first "
                       "tenth of each launch left out (both loops starting).")
    table.notes.append("Ratios are medians of per-round ratios (interleaved rounds), the verdicts judged on them; "
                       "DATA: the hand-written coupling (a DATA connection, the newest value read once).")
    table.notes.append(f"load average before the run: {load:.2f} on {os.cpu_count()} cores (the launches' own "
                       "processes not included).")
    _report.emit("bench_flowvr", args, [table], {"rounds": rounds, "verdicts": verdicts})

    def draw(plt: Any) -> Any:
        figure, (left, right) = plt.subplots(1, 2, figsize=(11, 3.6))
        coupled = VARIANTS[1:]
        y = np.arange(len(coupled))
        left.barh(y - 0.2, [med(v, "age_p50") * 1e3 for v in coupled], 0.4, label="p50", color="#4c72b0")
        left.barh(y + 0.2, [med(v, "age_p99") * 1e3 for v in coupled], 0.4, label="p99", color="#dd8452")
        left.set_yticks(y, coupled)
        left.set_xlabel("age of the value the consumer gets (ms)")
        left.set_title("1 kHz producer -> 60 Hz consumer")
        left.legend()
        right.barh(VARIANTS, [med(v, "period_error_p99") * 1e6 for v in VARIANTS], color="#55a868")
        right.set_xlabel("producer's p99 period error (us)")
        right.set_title("the producer's timing")
        figure.tight_layout()
        return figure

    _report.save_plot(args, draw)


if __name__ == "__main__":
    main()
