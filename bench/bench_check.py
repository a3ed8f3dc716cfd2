"""``--check`` of large applications: load and build N components, entry points scanned once.

What ``coco-launch app.xml --check`` does before it prints (load the file, build every component),
for applications of N ``MovingAverage`` components in N/40 periodic activities:
- *one scan*: this version; the ``coco.components`` entry points are scanned once per process.
- *scan per component* (anchor): the same build with the entry points scanned again for each
  component, as before (each scan reads every installed distribution's metadata). Measured for the
  smaller sizes only, and extrapolated linearly to the largest, which took minutes.
Goal: a ``--check`` of 4,000 components in under 5 s (it took 55 s when the issue was filed, 150 s on
this machine before the change).

    PYTHONPATH=coco_core .venv/bin/python bench/bench_check.py [--json PATH] [--no-plot]
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from typing import Any
from unittest import mock

import _report
from _table import Table, fmt_ratio, verdict

from coco_core import registry
from coco_core.builder import build_application
from coco_core.xml import parse_application_string

SIZES = [250, 1000, 4000]
ANCHOR_SIZES = [250, 1000]
GOAL_SIZE, GOAL_S = 4000, 5.0
ONE_SCAN, PER_COMPONENT = "one scan", "scan per component"


def application(count: int) -> str:
    """An application file of ``count`` components, one element a line as people write them."""
    components = "\n".join(f"<component><task>MovingAverage</task><name>m{i}</name></component>"
                           for i in range(count))
    activities = "\n".join(
        '<activity><schedule period="10"/><components>\n'
        + "\n".join(f'<component name="m{j}"/>' for j in range(i, min(i + 40, count)))
        + "\n</components></activity>"
        for i in range(0, count, 40)
    )
    return f"<package>\n<components>\n{components}\n</components>\n<activities>\n{activities}\n</activities>\n</package>"


@contextlib.contextmanager
def scan_per_component() -> Iterator[None]:
    """The anchor: every component lookup scans the entry points again, as before the change."""
    load = registry.load

    def rescanning(task: str, library: str = "") -> Any:
        registry._installed.cache_clear()
        return load(task, library)

    with mock.patch.object(registry, "load", rescanning):
        yield


def check_seconds(text: str, count: int) -> float:
    """Seconds to load and build ``text`` (a fresh scan first, as in a new process)."""
    registry._installed.cache_clear()
    start = time.perf_counter()
    app = build_application(parse_application_string(text))
    elapsed = time.perf_counter() - start
    if len(app.components) != count:
        raise AssertionError(f"built {len(app.components)} components, expected {count}")
    return elapsed


def measure() -> tuple[dict[tuple[str, int], float], float | None]:
    times: dict[tuple[str, int], float] = {}
    with _report.LoadMeter() as load:
        for count in SIZES:
            text = application(count)
            times[(ONE_SCAN, count)] = min(check_seconds(text, count) for _ in range(3))
            print(f"{ONE_SCAN:>20} {count:5d} components: {times[(ONE_SCAN, count)]:.3f} s", flush=True)
            if count in ANCHOR_SIZES:
                with scan_per_component():
                    times[(PER_COMPONENT, count)] = check_seconds(text, count)
                print(f"{PER_COMPONENT:>20} {count:5d} components: {times[(PER_COMPONENT, count)]:.3f} s", flush=True)
    return times, load.others


def tables(times: dict[tuple[str, int], float], others: float | None) -> tuple[list[Table], dict[str, Any]]:
    largest_anchor = ANCHOR_SIZES[-1]
    per_component = times[(PER_COMPONENT, largest_anchor)] / largest_anchor
    table = Table("--check: load and build N components (seconds, best of 3 for one scan)",
                  ["components", ONE_SCAN, PER_COMPONENT, "anchor / one scan", f"goal: {GOAL_SIZE} in < {GOAL_S:g} s"])
    results: dict[str, Any] = {}
    for count in SIZES:
        one = times[(ONE_SCAN, count)]
        measured = (PER_COMPONENT, count) in times
        anchor = times[(PER_COMPONENT, count)] if measured else per_component * count
        ok = one < GOAL_S if count == GOAL_SIZE else None
        table.add(f"{count:,}", f"{one:.2f} s", f"{anchor:.1f} s" + ("" if measured else " (extrapolated)"),
                  fmt_ratio(anchor / one), verdict(ok))
        results[str(count)] = {"one_scan_s": one, "scan_per_component_s": anchor,
                               "anchor_measured": measured, "goal_met": ok}
    table.notes.append(f"the anchor scans the entry points for every component ({per_component * 1e3:.0f} ms "
                       f"per component at {largest_anchor:,}); at {GOAL_SIZE:,} it is extrapolated from that rate.")
    if others is not None:
        table.notes.append(f"other processes used {others:.0%} of the machine's cores meanwhile.")
    return [table], results


def draw(times: dict[tuple[str, int], float]):
    def figure(plt: Any) -> Any:
        fig, ax = plt.subplots(figsize=(7, 4.5))
        ax.plot(SIZES, [times[(ONE_SCAN, n)] for n in SIZES], marker="o", label=ONE_SCAN)
        ax.plot(ANCHOR_SIZES, [times[(PER_COMPONENT, n)] for n in ANCHOR_SIZES], marker="o",
                label=f"{PER_COMPONENT} (anchor)")
        ax.axhline(GOAL_S, color="grey", linestyle="--", label=f"goal at {GOAL_SIZE:,}: {GOAL_S:g} s")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("components in the application (log)")
        ax.set_ylabel("load + build (s, log)")
        ax.set_title("--check of large applications")
        ax.legend()
        ax.grid(True, which="major", alpha=0.3)
        return fig

    return figure


def main() -> None:
    args = _report.parser("bench_check", __doc__.splitlines()[0]).parse_args()
    times, others = measure()
    t, results = tables(times, others)
    _report.emit("bench_check", args, t, results)
    _report.save_plot(args, draw(times))


if __name__ == "__main__":
    main()
