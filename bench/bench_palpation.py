"""Remote palpation end to end: the app with its processes against the same app in one process.

``config/palpation_replay.xml`` (the paper's section 6.1) on a generated session, run by the
installed ``coco-launch`` twice per round on the same session with the same arguments (the hand at
half speed, as the app's tests run it): as written
(seven processes: launcher, hand, remote, haptics, stream, local, view) and with its ``<process>`` elements removed
(every activity in the launcher's process). Rounds alternate the order, so that the shared machine's
noise falls on both alike; by default at the paper's 60 Hz display (``display_period`` 16 ms) and at
the app's default 50 ms, and with ``stride`` 1 (every depth pixel with depth in the touchable
structure: the goal's "every point", the app's default).

Per run, from the app's own ``summary.json`` (PalpationSummary) and its ``--profile`` at exit:
- sensor-to-display latency p50/p99: the remote camera's frames from their acquisition (RgbdCameraReader,
  remote process) to the view's pixels read back (GLManager.latency), and the same split by step,
  from the stamps the frame carries: *sent* (acquisition -> StreamingServer began the packet: the
  hand-over in the remote activity; the packet's header takes this time before the encoding),
  *received* (-> StreamingReceiver decoded it: JPEG + Zstandard encoding, TCP, the receiver's
  wake-up by its socket, decoding), *frame start* (-> the view's update began and the scene
  took the frame: the hand-off across processes and the wait for the display period), *drawn* (->
  every peer read its input, uploaded and drew, and the context finished: the renderer), *read back*
  (-> the pixels copied out of the framebuffer);
- sensor-to-touchable latency: the same frame to its KD-tree structure built, by step: sent,
  received, *built* (-> KDTreeBuilder finished the structure of the frame's depth: the hand-off to
  its activity and the copy of the depth; until issue 34 a *meshed* step came before it, the
  MeshReconstructor whose vertices the structure was built over);
- the haptic loop's rate and its period error p99, the runtime's own figure (wake-up - deadline,
  the profile's), against an idle 1 kHz activity's under the same scheduling as the loop in that
  layout (``bench_processes.anchor``: SCHED_FIFO at the file's priority, its spin, and, in the
  layout with processes, a process of its own with the memory locked and the garbage collector
  between cycles; read from the application file as run), measured before each round's runs at each
  display period: the ratio is to the median of those anchors; with the loop's missed deadlines and
  worst case: a loop that missed a deadline, or woke later than ``bench_processes.WORST_BOUND``
  periods, is not a PASS whatever its p99;
- KD-tree updates per second (arrivals at the haptic side) and points per structure;
- display frames per second: the view's display cycles over the run's time (the profile's);
- CPU by process (the profile's ``cpu cores``: CPU time / time lived), the two cores' budget.

Goals (issue 34, on this 2-core machine with its CPU renderer; issue 20 asked a 25 ms median):
sensor-to-display (camera acquisition to the view's pixels) median <= 60 ms, mean <= 75 ms (the
paper's average, on twice the cores and a GPU), p99 <= 120 ms; the display >= 30 fps at the 16 ms
period; the haptic p99 period error within 2x of the idle activity's, no deadline missed and the
worst case within half a period; a structure for every camera frame (30 Hz) over every point, and
sensor-to-touchable median <= 40 ms. A GPU figure is not measured here (no GPU on this machine).

    source install/setup.bash && .venv/bin/python bench/bench_palpation.py [--quick] [--rounds N] [--no-plot]
"""

from __future__ import annotations

import json
import os
import re
import socket
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import _report
from _table import Table, fmt_ratio, fmt_time_ns, verdict

REPO = _report.REPO
APP = REPO / "config" / "palpation_replay.xml"
LAUNCH = REPO / "install" / "coco_core" / "lib" / "coco_core" / "coco-launch"
SESSION_SCRIPT = REPO / "install" / "coco_ros" / "lib" / "coco_ros" / "palpation-session"
LAYOUTS = ("processes", "one process")
DIAGNOSTICS = {"processes, stride 2": ["stride:=2"], "processes, no display": ["display:=false"]}
"""Rows that say what bounds the figures, at the first display period: stride 2 (a quarter of the
points into the touchable structure), and no view at all (what the renderer costs the
rest). The launcher takes the last value of an argument: these override the benchmark's."""
GOAL_LATENCY_MS = 60.0
"""Issue 34: sensor-to-pixel median on this 2-core machine without a GPU (issue 20 asked 25 ms)."""
GOAL_LATENCY_MEAN_MS = 75.0
"""Issue 34: the mean, the paper's figure (an average, on a 4-core i7 with an embedded GPU)."""
GOAL_LATENCY_P99_MS = 120.0
GOAL_DISPLAY_FPS = 30.0
"""Issue 34, at the 16 ms period: judged only where the period allows it (50 ms: 20 fps at most)."""
GOAL_HAPTIC_RATIO = 2.0
GOAL_HAPTIC_HZ = 990.0
GOAL_INTERVAL_P99_MS = 0.3
"""Issue 34 keeps what held: the renderer's samples at >= 990 Hz, their interval p99 <= 0.3 ms."""
GOAL_TREE_HZ = 30.0
GOAL_TOUCHABLE_MS = 40.0
"""Issue 34: a frame's acquisition to its structure usable by the haptic loop, median."""
CAMERA_HZ = 30.0
HAND_RATE = 0.5
"""The hand replayed at half speed (the camera at its own 30 Hz), as the app's tests do: the run lasts
twice the session, and the calibration touch registers on a loaded machine (at full speed it was
missed at times in one process with every point meshed: then no haptic sample is rendered)."""
EARLIER_ANCHOR = "normal class, launcher's process (runs before issue 34)"
"""The scheduling of the anchors of a JSON written before the anchor took the loop's (``--from-json``)."""
DISPLAY_STEPS = ("sent", "received", "frame_start", "drawn", "read_back")
TOUCH_STEPS = ("sent", "received", "built")


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def one_process_file(folder: Path) -> Path:
    """The application file with its process level removed (as test_palpation_app does); its one
    file-relative path (the hand's mesh) made absolute, since the copy lives elsewhere."""
    text = APP.read_text()
    flat = re.sub(r"\s*</?process\b[^>]*>", "", text).replace("$(dirname)", str(APP.parent))
    if "<process" in flat or flat.count("<activity ") != text.count("<activity "):
        raise SystemExit(f"could not remove the process level of {APP}")
    path = folder / "palpation_one_process.xml"
    path.write_text(flat)
    return path


def session(path: Path) -> Path:
    """The session bag, generated by palpation-session when missing (like run_app.sh palpation)."""
    if not (path / "metadata.yaml").exists():
        if not SESSION_SCRIPT.exists():
            raise SystemExit(f"{SESSION_SCRIPT} is missing: build the workspace first (scripts/setup.sh)")
        print(f"generating the session {path} (first run only)", flush=True)
        subprocess.run([str(SESSION_SCRIPT), str(path), "--quiet"], check=True)
    return path


def profile(stdout: str) -> dict[str, Any]:
    """What the launcher's profile at exit says: run time, per process CPU, per activity cycles,
    overruns and period error (us). Without the process level its tables have no process column."""
    elapsed = re.search(r"^Profile of application '[^']*' after ([0-9.]+) s", stdout, re.M)
    facts: dict[str, Any] = {"elapsed_s": float(elapsed.group(1)) if elapsed else float("nan"),
                             "cpu_s": {}, "activities": {}}
    facts["cores"] = {}
    for match in re.finditer(r"^(\w+)\s+\d+\s+([0-9.]+)\s+[0-9.]+\s+([0-9.]+|-)$", stdout, re.M):
        facts["cpu_s"][match.group(1)] = float(match.group(2))
        if match.group(3) != "-":
            facts["cores"][match.group(1)] = float(match.group(3))
    pattern = (r"^(?:(\w+)\s+)?(\w+)(?: \(main\))?\s+"
               r"(?:periodic [0-9.]+ m?s|triggered(?:, at most every [0-9.]+ ms)?)\s+(\d+)\s+(\d+)\s+"
               r"(?:([0-9.]+) / ([0-9.]+) / ([0-9.]+)|-)")
    for match in re.finditer(pattern, stdout, re.M):
        process, activity, cycles, overruns, p50, p99, top = match.groups()
        facts["activities"][activity] = {
            "process": process or "launcher", "cycles": int(cycles), "overruns": int(overruns),
            "p50_us": float(p50) if p50 else None, "p99_us": float(p99) if p99 else None,
            "max_us": float(top) if top else None}
    return facts


def run_app(app: Path, bag: Path, period: int, stride: int, folder: Path, extra: list[str]) -> dict[str, Any]:
    """One run of the application to the end of the hand's recording; its summary and profile."""
    output = folder / "output"
    command = [str(LAUNCH), str(app), f"bag:={bag}", f"output:={output}", f"rate:={HAND_RATE}",
               f"display_period:={period}",
               f"stride:={stride}", f"stream:=tcp://127.0.0.1:{free_port()}", "--profile", "3600",
               *extra, "--duration", "120"]
    with _report.LoadMeter(children=True) as cpu:  # the launchers it waits for are its own
        result = subprocess.run(command, cwd=REPO, capture_output=True, text=True, timeout=600,
                                env={**os.environ, "PYTHONUNBUFFERED": "1"})
    if not (output / "summary.json").exists():  # a run that did not reach its stop
        raise SystemExit(f"{' '.join(command)} failed ({result.returncode}):\n{result.stderr[-4000:]}")
    # A run whose calibration touch did not register (the tracker starved on a loaded machine) exits
    # non-zero by design: its timing figures stand, its haptic samples (none before the registration) not.
    summary = json.loads((output / "summary.json").read_text())
    facts = profile(result.stdout)
    display = facts["activities"].get("display", {})
    haptics = facts["activities"].get("haptics", {})
    camera = summary["display_latency_ms"].get("camera", {})
    return {
        "latency_ms": {"frames": camera.get("frames", 0), "median": camera.get("median"), "p99": camera.get("p99"),
                       "mean": camera.get("mean")},
        "display_steps_ms": summary.get("display_steps_ms", {}).get("camera", {}),
        "touchable_ms": summary["kdtree"].get("latency_ms", {}),
        "touchable_steps_ms": summary["kdtree"].get("steps_ms", {}),
        "display_shares": summary.get("display_step_shares", {}).get("camera", {}),
        "touchable_shares": summary["kdtree"].get("step_shares", {}),
        "haptic_rate_hz": summary["haptics"]["rate_hz"],
        "haptic_interval_p99_ms": summary["haptics"]["period_error_ms"].get("p99"),
        "haptic_p99_us": haptics.get("p99_us"), "haptic_cycles": haptics.get("cycles"),
        "haptic_missed": haptics.get("overruns"), "haptic_max_us": haptics.get("max_us"),
        "process_cores": facts["cores"],
        "tree_hz": summary["kdtree"]["rate_hz"], "tree_updates": summary["kdtree"]["updates"],
        "tree_points": summary["kdtree"]["points_median"],
        "tree_build_ms": summary["kdtree"]["build_ms"].get("median"),
        "stream_frames": summary["stream"]["frames"], "stream_dropped": summary["stream"]["dropped"],
        "display_fps": display["cycles"] / facts["elapsed_s"] if display and facts["elapsed_s"] > 0 else None,
        "display_missed": display.get("overruns"),
        "elapsed_s": facts["elapsed_s"], "cpu_s": facts["cpu_s"], "others": cpu.others, "app_cores": cpu.own,
        "registered": summary["registration_residual_mm"] is not None, "exit": result.returncode,
    }


def scheduling(app: Path, period: int, stride: int) -> Any:
    """The haptic loop's scheduling in ``app`` as the benchmark runs it (bench_processes.Scheduling)."""
    import bench_processes

    return bench_processes.load_scheduling(app, "haptics", {"display_period": str(period), "stride": str(stride)})


def idle_anchor(how: Any, seconds: float) -> dict[str, Any]:
    """An idle 1 kHz activity under the haptic loop's scheduling ``how``: the runtime's and the
    machine's floor for that loop."""
    import bench_processes

    return bench_processes.anchor(how, seconds)


def median(values: list[Any]) -> float | None:
    present = [float(v) for v in values if v is not None]
    return statistics.median(present) if present else None


def combine(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """One condition's runs: the median of each figure over the rounds."""
    def pick(*keys: str) -> list[Any]:
        values = []
        for run in runs:
            value: Any = run
            for key in keys:
                value = value.get(key) if isinstance(value, dict) else None
            values.append(value)
        return values

    out: dict[str, Any] = {"runs": len(runs)}
    for key in ("haptic_rate_hz", "haptic_interval_p99_ms", "haptic_p99_us", "tree_hz", "tree_points",
                "tree_build_ms", "display_fps", "others", "app_cores"):
        out[key] = median(pick(key))
    out["registered"] = f"{sum(bool(v) for v in pick('registered'))}/{len(runs)}"
    out["anchor"] = runs[0].get("anchor", EARLIER_ANCHOR)
    out["haptic_missed"] = sum(v or 0 for v in pick("haptic_missed"))
    out["haptic_max_us"] = max((v for v in pick("haptic_max_us") if v is not None), default=None)
    out["display_shares"] = {step: median(pick("display_shares", step)) for step in DISPLAY_STEPS}
    out["touchable_shares"] = {step: median(pick("touchable_shares", step)) for step in TOUCH_STEPS}
    processes = dict.fromkeys(name for run in runs for name in run.get("process_cores", {}))
    out["process_cores"] = {name: median(pick("process_cores", name)) for name in processes}
    out["latency_median"] = median(pick("latency_ms", "median"))
    out["latency_p99"] = median(pick("latency_ms", "p99"))
    out["latency_mean"] = median(pick("latency_ms", "mean"))
    out["latency_frames"] = sum(v or 0 for v in pick("latency_ms", "frames"))
    out["stream_frames"] = sum(v or 0 for v in pick("stream_frames"))
    out["touchable_median"] = median(pick("touchable_ms", "median"))
    out["display_steps"] = {step: median(pick("display_steps_ms", step, "median")) for step in DISPLAY_STEPS}
    out["touchable_steps"] = {step: median(pick("touchable_steps_ms", step, "median")) for step in TOUCH_STEPS}
    return out


def us(value: float | None) -> str:
    """A duration given in microseconds, in the unit that keeps it readable."""
    return "n/a" if value is None else fmt_time_ns(1e3 * value)


def ms(value: float | None, digits: int = 1) -> str:
    return "n/a" if value is None else f"{value:.{digits}f} ms"


def bound(steps: dict[str, float | None], shares: dict[str, float | None]) -> str:
    """The step that takes the largest share of the path, as 'name (x ms median, y% of the path)': the
    share is the median over frames of that step / the frame's whole path (PalpationSummary), so it
    explains the path's median; a share of the summed step medians explained no figure."""
    known = {name: value for name, value in shares.items() if value is not None}
    if not known:
        return "n/a"
    name = max(known, key=lambda n: known[n])
    step = steps.get(name)
    return (f"{name.replace('_', ' ')} ({'n/a' if step is None else f'{step:.0f} ms'} median, "
            f"{100 * known[name]:.0f}% of the path: median over frames)")


Runs = dict[tuple[int, str], list[dict[str, Any]]]
"""The runs of each condition (display period, layout), in the order they first ran."""


def measure(args: Any, bag: Path) -> tuple[Runs, list[dict[str, Any]]]:
    """Every round: at each display period the idle anchor, then the app's runs."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    runs: Runs = {}
    idle: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as scratch:
        flat = one_process_file(Path(scratch))
        variants: dict[str, tuple[Path, list[str]]] = {"processes": (APP, []), "one process": (flat, [])}
        if not args.no_diagnostics:
            variants.update({name: (APP, extra) for name, extra in DIAGNOSTICS.items()})
        for round_ in range(args.rounds):
            for index, period in enumerate(args.periods):
                order = list(LAYOUTS if round_ % 2 == 0 else LAYOUTS[::-1])
                if index == 0:
                    order += [name for name in variants if name not in LAYOUTS]
                # An anchor per scheduling of the haptic loop just before the runs: the shared machine's
                # load moves a lot (the ratio is to the median of all the anchors of that scheduling,
                # which one caught in a quiet or busy moment cannot sway).
                how = {layout: scheduling(variants[layout][0], period, args.stride) for layout in order}
                anchors: dict[str, float] = {}
                for loop in dict.fromkeys(how.values()):
                    with _report.LoadMeter() as load:
                        idle.append(idle_anchor(loop, args.idle_seconds))
                    idle[-1]["others"] = load.others
                    anchors[loop.describe()] = idle[-1]["p99_ns"] / 1e3
                    print(f"round {round_ + 1}, {period} ms: idle 1 kHz activity ({loop.describe()}) p99 "
                          f"{fmt_time_ns(idle[-1]['p99_ns'])}, max {fmt_time_ns(idle[-1]['max_ns'])}, "
                          f"{idle[-1]['missed']} missed", flush=True)
                for layout in order:
                    app, extra = variants[layout]
                    with tempfile.TemporaryDirectory(dir=scratch) as folder:
                        run = run_app(app, bag, period, args.stride, Path(folder), extra)
                    run["anchor"] = how[layout].describe()
                    run["idle_p99_us"] = anchors[run["anchor"]]
                    runs.setdefault((period, layout), []).append(run)
                    print(f"round {round_ + 1}, {period} ms, {layout}: latency median "
                          f"{ms(run['latency_ms']['median'])}, haptic p99 {us(run['haptic_p99_us'])} "
                          f"(max {us(run['haptic_max_us'])}, {run['haptic_missed']} missed), "
                          f"KD-tree {run['tree_hz'] or 0:.1f} Hz, display {run['display_fps'] or 0:.1f} fps, "
                          f"app {run['app_cores'] or 0:.2f} cores",
                          flush=True)
    return runs, idle


def main() -> None:
    parser = _report.parser("bench_palpation", __doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one round, the 60 Hz display only, no diagnostic rows")
    parser.add_argument("--no-diagnostics", action="store_true",
                        help=f"leave out the diagnostic rows ({', '.join(DIAGNOSTICS)})")
    parser.add_argument("--rounds", type=int, default=2, help="rounds per display period (default 2)")
    parser.add_argument("--periods", type=int, nargs="+", default=[16, 50],
                        help="display periods in ms (default 16 50: the paper's 60 Hz and the app's default)")
    parser.add_argument("--stride", type=int, default=1, help="every stride-th pixel into the touchable structure (default 1: every point)")
    parser.add_argument("--session", default=str(REPO / "out" / "palpation_session"),
                        help="the session bag (generated when missing; default: run_app.sh palpation's)")
    parser.add_argument("--idle-seconds", type=float, default=4.0, help="seconds of the idle 1 kHz anchor per round")
    parser.add_argument("--from-json", metavar="PATH",
                        help="run nothing: print the tables and draw the plot of an earlier run's JSON")
    args = parser.parse_args()
    if args.quick:
        args.rounds, args.periods, args.idle_seconds, args.no_diagnostics = 1, args.periods[:1], 2.0, True
    if args.from_json:
        earlier = json.loads(Path(args.from_json).read_text())["results"]
        runs: Runs = {}
        for key, condition in earlier["conditions"].items():
            period, layout = key.split(" ms, ", 1)
            runs[(int(period), layout)] = condition["runs"]
        report(args, runs, earlier["idle"], max(len(r) for r in runs.values()), earlier["stride"],
               Path(earlier["session"]))
        return
    if not LAUNCH.exists():
        raise SystemExit(f"{LAUNCH} is missing: build the workspace first (scripts/setup.sh)")
    bag = session(Path(args.session))
    runs, idle = measure(args, bag)
    report(args, runs, idle, args.rounds, args.stride, bag)


def report(args: Any, runs: Runs, idle: list[dict[str, Any]], rounds: int, stride: int, bag: Path) -> None:
    """The tables, the verdicts and the plot (and the JSON when asked)."""
    import bench_processes

    bound_us = bench_processes.WORST_BOUND * 1e3
    for anchor in idle:
        anchor.setdefault("scheduling", EARLIER_ANCHOR)
    kinds = dict.fromkeys(r["scheduling"] for r in idle)
    anchors = {kind: [r for r in idle if r["scheduling"] == kind] for kind in kinds}
    idle_p99 = {kind: statistics.median(r["p99_ns"] for r in found) / 1e3 for kind, found in anchors.items()}
    results: dict[str, Any] = {"idle": idle, "idle_p99_us": idle_p99, "stride": stride,
                               "session": str(bag), "conditions": {}}
    table = Table(f"Remote palpation app, {rounds} round(s), stride {stride} (medians over the rounds)",
                  ["display", "layout", "latency p50", "mean", "p99",
                   f"goal p50 <= {GOAL_LATENCY_MS:.0f}, mean <= {GOAL_LATENCY_MEAN_MS:.0f}, p99 <= {GOAL_LATENCY_P99_MS:.0f} ms",
                   "haptic rate", "haptic p99", "/ idle p99", "missed", "max",
                   f"goal <= {GOAL_HAPTIC_RATIO:.0f}x, none missed, max <= {bound_us:.0f} us",
                   "KD-tree", "points", f"goal >= {GOAL_TREE_HZ:.0f} Hz", "display fps", f"goal >= {GOAL_DISPLAY_FPS:.0f}", "camera frames shown",
                   "registered",
                   "app CPU", "others' CPU"])
    anchor_table = Table("The haptic loop's anchors: an idle 1 kHz activity under the loop's scheduling, "
                         "alone, before each round's runs (medians over the anchors)",
                         ["scheduling", "anchors", "p99", "max (worst anchor)", "missed (all anchors)"])
    for kind, found in anchors.items():
        anchor_table.add(kind, len(found), fmt_time_ns(1e3 * idle_p99[kind]), fmt_time_ns(max(r["max_ns"] for r in found)),
                         sum(r["missed"] for r in found))
    anchor_table.notes.append(f"p99 ranged {fmt_time_ns(min(r['p99_ns'] for r in idle))} - "
                              f"{fmt_time_ns(max(r['p99_ns'] for r in idle))} over all anchors as the machine's load "
                              "moved")
    cpu_names = list(dict.fromkeys(name for condition in runs.values() for run in condition
                                   for name in run.get("process_cores", {})))
    cpu_table = Table("CPU by process (cores: CPU time / time lived, start-up included; medians over the rounds)",
                      ["display", "layout", *cpu_names, "all"])
    steps = Table("Where the latency goes: step medians (ms, each from the step before), then the path's median",
                  ["path / step", *[f"{p} ms, {layout}" for (p, layout) in runs]])
    verdicts: list[str] = []
    for (period, layout), condition_runs in runs.items():
        c = combine(condition_runs)
        results["conditions"][f"{period} ms, {layout}"] = {"combined": c, "runs": condition_runs}
        anchor_us = idle_p99.get(c["anchor"], float("nan"))
        ratio = (bench_processes.ratio_of(1e3 * c["haptic_p99_us"], 1e3 * anchor_us)
                 if c["haptic_p99_us"] is not None else float("nan"))
        loop = {"missed": c["haptic_missed"], "max_ns": 1e3 * (c["haptic_max_us"] if c["haptic_max_us"] is not None
                                                                else float("inf"))}
        haptic_ok = bench_processes.judged(loop, ratio, GOAL_HAPTIC_RATIO)
        haptic_p99 = "n/a" if c["haptic_p99_us"] is None else fmt_time_ns(1e3 * c["haptic_p99_us"])
        worst = "n/a" if c["haptic_max_us"] is None else fmt_time_ns(1e3 * c["haptic_max_us"])
        cores = c["process_cores"]
        cpu_table.add(f"{period} ms", layout, *["-" if cores.get(n) is None else f"{cores[n]:.2f}" for n in cpu_names],
                      f"{sum(v for v in cores.values() if v is not None):.2f}")
        lat, mean, p99 = c["latency_median"], c["latency_mean"], c["latency_p99"]
        latency_ok = None if lat is None else (lat <= GOAL_LATENCY_MS and p99 is not None and p99 <= GOAL_LATENCY_P99_MS
                                               and (mean is None or mean <= GOAL_LATENCY_MEAN_MS))
        fps = c["display_fps"]
        fps_judged = period <= 1000.0 / GOAL_DISPLAY_FPS
        table.add(f"{period} ms", layout, ms(lat), ms(mean), ms(p99), verdict(latency_ok),
                  "-" if c["haptic_rate_hz"] is None else f"{c['haptic_rate_hz']:.0f} Hz", haptic_p99, fmt_ratio(ratio),
                  c["haptic_missed"], worst,
                  verdict(haptic_ok), f"{c['tree_hz'] or 0:.1f} Hz",
                  f"{c['tree_points'] or 0:,.0f}", verdict((c["tree_hz"] or 0) >= GOAL_TREE_HZ * 0.97),
                  "-" if fps is None else f"{fps:.1f}", verdict(None if fps is None or not fps_judged else
                                                               fps >= GOAL_DISPLAY_FPS * 0.97),
                  f"{c['latency_frames']} of {c['stream_frames']}" if fps is not None else "-",
                  c["registered"],
                  "n/a" if c["app_cores"] is None else f"{c['app_cores']:.2f} cores",
                  "n/a" if c["others"] is None else f"{100 * c['others']:.0f}%")
        if lat is not None:
            misses = [f"{name} {value:.0f} ms > {goal:.0f} ms ({value / goal:.2f}x)"
                      for name, value, goal in (("median", lat, GOAL_LATENCY_MS), ("mean", mean, GOAL_LATENCY_MEAN_MS),
                                                ("p99", p99, GOAL_LATENCY_P99_MS))
                      if value is not None and value > goal]
            verdicts.append(f"{period} ms display, {layout}: sensor-to-display median {lat:.0f} ms, mean {ms(mean, 0)}, "
                            f"p99 {ms(p99, 0)}: " + ("PASS" if latency_ok else f"MISS ({', '.join(misses)})")
                            + f" (goal median {GOAL_LATENCY_MS:.0f}, mean {GOAL_LATENCY_MEAN_MS:.0f}, p99 "
                            f"{GOAL_LATENCY_P99_MS:.0f} ms; paper 75 ms average: mean {ms(mean, 0)}); bound by "
                            + bound(c["display_steps"], c["display_shares"]))
        if fps is not None and fps_judged:
            verdicts.append(f"{period} ms display, {layout}: display {fps:.1f} fps, "
                            + ("PASS" if fps >= GOAL_DISPLAY_FPS * 0.97 else f"MISS by {GOAL_DISPLAY_FPS / max(fps, 1e-9):.2f}x")
                            + f" (goal {GOAL_DISPLAY_FPS:.0f} fps at the {period} ms period)")
        verdicts.append(f"{period} ms display, {layout}: haptic p99 period error "
                        f"{haptic_p99} = {fmt_ratio(ratio)} the idle activity's ({fmt_time_ns(1e3 * anchor_us)}, "
                        f"{c['anchor']}, same rounds), {c['haptic_missed']} missed, worst {worst}: "
                        + ("PASS" if haptic_ok else
                           f"MISS ({bench_processes.why_missed(loop, ratio, GOAL_HAPTIC_RATIO)})")
                        + f" (goal {GOAL_HAPTIC_RATIO:.0f}x, none missed, worst <= {bound_us:.0f} us; rate "
                        + ("- : no run registered" if c["haptic_rate_hz"] is None else f"{c['haptic_rate_hz']:.0f} Hz")
                        + ")")
        interval, rate = c["haptic_interval_p99_ms"], c["haptic_rate_hz"]
        if interval is not None and rate is not None:
            kept = rate >= GOAL_HAPTIC_HZ and interval <= GOAL_INTERVAL_P99_MS
            verdicts.append(f"{period} ms display, {layout}: haptic samples at {rate:.0f} Hz, interval p99 "
                            f"{interval:.2f} ms: " + ("PASS" if kept else "MISS")
                            + f" (issue 34 keeps: >= {GOAL_HAPTIC_HZ:.0f} Hz, interval p99 <= {GOAL_INTERVAL_P99_MS} ms)")
        tree_hz = c["tree_hz"] or 0.0
        touchable = c["touchable_median"]
        verdicts.append(f"{period} ms display, {layout}: KD-tree {tree_hz:.1f} Hz over {c['tree_points'] or 0:,.0f} "
                        "points, " + ("PASS" if tree_hz >= GOAL_TREE_HZ * 0.97 else
                                      f"MISS by {GOAL_TREE_HZ / max(tree_hz, 1e-9):.1f}x")
                        + f" (goal {GOAL_TREE_HZ:.0f} Hz); sensor-to-touchable median {ms(touchable)}, "
                        + ("n/a" if touchable is None else "PASS" if touchable <= GOAL_TOUCHABLE_MS else
                           f"MISS by {touchable / GOAL_TOUCHABLE_MS:.1f}x")
                        + f" (goal {GOAL_TOUCHABLE_MS:.0f} ms), bound by {bound(c['touchable_steps'], c['touchable_shares'])}")
    for name, path, total in (("display", DISPLAY_STEPS, "latency_median"),
                              ("touchable", TOUCH_STEPS, "touchable_median")):
        for step in path:
            key = "display_steps" if name == "display" else "touchable_steps"
            steps.add(f"{name}: {step.replace('_', ' ')}",
                      *[ms(combine(r)[key][step]) for r in runs.values()])
        steps.add(f"{name}: acquisition -> {path[-1].replace('_', ' ')}",
                  *[ms(combine(r)[total]) for r in runs.values()])
    table.notes += [
        "latency: the remote camera's frames, acquisition (remote process) -> the view's pixels read back "
        "(GLManager.latency); haptic p99: the runtime's period error (wake-up - deadline) of the 1 ms "
        "activity; / idle p99: against a lone 1 kHz activity's under the loop's scheduling in that layout "
        "(the anchors' table), measured before each round's runs at each display period: the median of those "
        "anchors (p99s under 1 us compared as 1 us: the clock's and the spin's grain); missed: the loop's deadlines missed (the profile's overruns, all rounds); max: its worst "
        "period error (all rounds)",
        f"KD-tree: structures arriving at the haptic side per second (the camera sends {CAMERA_HZ:.0f} Hz); "
        "display fps: display cycles / run time (a cycle starts when a camera frame or a hand pose arrives, "
        f"at most one a period; judged at periods that allow {GOAL_DISPLAY_FPS:.0f} fps); camera frames shown: those "
        "whose pixels were read back, of the frames the receiver delivered (all rounds; the others were "
        "superseded by a newer one before the view took them); registered: runs whose calibration touch registered the "
        "hand (before it the haptic loop runs but renders no sample: its rate is from the samples); app CPU: "
        "the cores the app's processes used (CPU time / wall time, start-up included); others' CPU: both "
        "cores' share used by processes other than the benchmark and the app",
    ]
    steps.notes += [
        "sent: the hand-over to the server in the remote process; received: encoding, TCP, the receiver's "
        "wake-up by its socket, decoding; frame start: "
        "hand-off to the view and the wait for its period; drawn: peers' input, upload, draw and the finished "
        "rasterisation; read back: pixels out; built: hand-off to KDTreeBuilder and the structure of the "
        "frame's depth",
        "the step medians do not add up to the path's median (each is a median of its own)",
    ]
    _report.emit("bench_palpation", args, [table, anchor_table, cpu_table, steps], results)
    for line in verdicts:
        print(line)

    def draw(plt: Any) -> Any:
        figure, axes = plt.subplots(1, 3, figsize=(15, 4.2))
        names = [f"{p} ms\n{layout.replace(', ', chr(10))}" for (p, layout) in runs]
        combined = [combine(r) for r in runs.values()]
        for axis, key, path, title in ((axes[0], "display_steps", DISPLAY_STEPS, "sensor -> display (step medians)"),
                                       (axes[1], "touchable_steps", TOUCH_STEPS, "sensor -> KD-tree (step medians)")):
            bottom = [0.0] * len(combined)
            for step in path:
                heights = [c[key][step] or 0.0 for c in combined]
                axis.bar(range(len(names)), heights, bottom=bottom, label=step.replace("_", " "))
                bottom = [b + h for b, h in zip(bottom, heights)]
            if key == "display_steps":
                axis.axhline(GOAL_LATENCY_MS, color="k", linestyle="--", linewidth=1, label=f"goal {GOAL_LATENCY_MS:.0f} ms (median)")
                axis.axhline(75, color="grey", linestyle=":", linewidth=1, label="paper 75 ms")
            axis.set_xticks(range(len(names)), names, fontsize=8)
            axis.set_ylabel("ms")
            axis.set_title(title)
            axis.legend(fontsize=7)
        right = axes[2]
        width = 0.4
        right.bar([i - width / 2 for i in range(len(names))], [c["tree_hz"] or 0 for c in combined], width,
                  label="KD-tree updates/s")
        right.bar([i + width / 2 for i in range(len(names))], [c["display_fps"] or 0 for c in combined], width,
                  label="display fps")
        right.axhline(GOAL_TREE_HZ, color="k", linestyle="--", linewidth=1, label="camera 30 Hz")
        for i, c in enumerate(combined):
            ratio = bench_processes.ratio_of(1e3 * (c["haptic_p99_us"] or 0.0), 1e3 * idle_p99.get(c["anchor"], 0.0))
            right.text(i, max(c["tree_hz"] or 0, c["display_fps"] or 0) + 1, f"haptic p99\n{ratio:.1f}x idle\n{c['haptic_missed']} missed",
                       ha="center", fontsize=7)
        right.set_xticks(range(len(names)), names, fontsize=8)
        right.set_ylabel("per second")
        right.set_title("rates (haptic p99 / idle, missed deadlines above)")
        right.set_ylim(0, 45)
        right.legend(fontsize=7, loc="upper right")
        figure.tight_layout()
        return figure

    _report.save_plot(args, draw)


if __name__ == "__main__":
    main()
