"""Applications that check channels between processes against the same application in one process.

An application here is one writer (``channel_components.Source`` or ``FrameSource``) and one or more
readers, each connection with the same policy; its *placement* puts the writer's and each reader's
activity in the launcher or in a child process. :func:`run` launches it with ``coco_core.launcher``
(with its ``<process>`` elements, or without them: the one-process reference), waits until every
reader says it is done, stops it with SIGINT and returns what the readers got and what the final
profile says. :func:`problems` lists what breaks the rules of one run (counters, order, payloads,
slots, /dev/shm) and :func:`differences` what differs between the two runs where they must agree.

Used by ``test_process_channels.py`` (a few seeded cases) and ``bench/soak_channels.py`` (many).
"""

from __future__ import annotations

import os
import random
import re
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

DATA = Path(__file__).parent
POLICIES = ("DATA", "BUFFER", "CIRCULAR", "POOL")
PLACES = ("", "p0", "p1", "p2")
"""Where an activity runs: the launcher ("") or a child process."""


@dataclass
class ReaderCase:
    mode: str
    """read, read_all or read_newest."""
    triggered: bool
    """Woken by the writes (event input), or periodic."""
    place: str
    hold: int = 0
    component: str = "Reader"
    die: bool = False
    watch: bool = False


@dataclass
class Case:
    """One generated application."""

    policy: str
    buffersize: int
    kind: str
    """int, array, records, or frame (POOL)."""
    size: int
    count: int
    batch: int
    writer_place: str
    readers: list[ReaderCase] = field(default_factory=list)
    source: str = ""
    """The writer's component class (default: Source, or FrameSource for POOL)."""
    period: float = 1.0
    """The writer's period, ms."""

    def lossless(self, reader: ReaderCase) -> bool:
        """Whether ``reader`` must get every value, in order, whatever the timing."""
        return self.policy in ("BUFFER", "CIRCULAR") and self.buffersize >= self.count and reader.mode != "read_newest"

    def describe(self) -> str:
        readers = ", ".join(f"{r.mode}/{'event' if r.triggered else 'periodic'}@{r.place or 'launcher'}"
                            + (f"/hold{r.hold}" if r.hold else "") for r in self.readers)
        return (f"{self.policy} {self.buffersize}, {self.count} x {self.kind} {self.size} B by {self.batch}, "
                f"writer@{self.writer_place or 'launcher'}, readers: {readers}")


def generate(seed: int, count: int = 200) -> Case:
    """A random application (policy, sizes, read modes, reader count, placement) from ``seed``."""
    rng = random.Random(seed)
    policy = rng.choice(POLICIES)
    frames = policy == "POOL"
    kind = "frame" if frames else rng.choice(("int", "array", "records"))
    size = {"int": 0, "frame": rng.choice((64, 8192, 300_000))}.get(kind, rng.choice((64, 6000, 300_000)))
    buffersize = rng.choice((1, 4, 16, count, count))
    readers = []
    refusing = policy == "BUFFER" and buffersize < count
    for _ in range(rng.randint(1, 3)):
        # A value a full BUFFER refuses wakes nobody: a triggered reader would wait for good.
        triggered = rng.random() < 0.5 and not refusing
        modes = ("read_all", "read_newest") if triggered else ("read", "read_all", "read_newest")
        readers.append(ReaderCase(rng.choice(modes), triggered, rng.choice(PLACES),
                                  hold=rng.choice((0, 0, 1)) if frames else 0))
    writer = rng.choice(PLACES)
    if all(reader.place == writer for reader in readers):  # at least one connection crosses processes
        writer = PLACES[(PLACES.index(writer) + 1) % len(PLACES)]
    return Case(policy, buffersize, kind, size, count, rng.choice((1, 5, 20)), writer, readers)


def xml(case: Case, folder: Path, processes: bool) -> str:
    """The application of ``case``; without ``processes``, every activity in the launcher."""
    frames = case.policy == "POOL"
    source = case.source or ("FrameSource" if frames else "Source")
    port = "frames" if frames else "out"
    parts = [f'<package name="channels">\n  <components>\n'
             f'    <component><name>src</name><task>channel_components:{source}</task><attributes>'
             f'<attribute name="count" value="{case.count}"/><attribute name="batch" value="{case.batch}"/>'
             f'<attribute name="size" value="{case.size}"/><attribute name="done" value="{folder}/src.done"/>'
             + ("" if frames else f'<attribute name="kind" value="{case.kind}"/>')
             + (f'<attribute name="path" value="{folder}/pool.txt"/>' if frames else "")
             + '</attributes></component>\n']
    for index, reader in enumerate(case.readers):
        parts.append(f'    <component><name>r{index}</name><task>channel_components:{reader.component}</task>'
                     f'<attributes><attribute name="count" value="{case.count}"/>'
                     f'<attribute name="mode" value="{reader.mode}"/><attribute name="kind" value="{case.kind}"/>'
                     f'<attribute name="size" value="{case.size}"/><attribute name="hold" value="{reader.hold}"/>'
                     f'<attribute name="path" value="{folder}/r{index}.txt"/>'
                     f'<attribute name="die" value="{str(reader.die).lower()}"/>'
                     f'<attribute name="source_done" value="{folder}/src.done"/>'
                     f'<attribute name="watch" value="{str(reader.watch).lower()}"/></attributes></component>\n')
    parts.append("  </components>\n  <connections>\n")
    for index in range(len(case.readers)):
        parts.append(f'    <connection data="{case.policy}" policy="LOCKED" buffersize="{case.buffersize}">'
                     f'<src task="src" port="{port}"/><dest task="r{index}" port="value"/></connection>\n')
    parts.append("  </connections>\n  <activities>\n")
    activities = [(case.writer_place, f'<activity name="writing"><schedule type="periodic" period="{case.period}"/>'
                                      '<components><component name="src"/></components></activity>')]
    for index, reader in enumerate(case.readers):
        schedule = '<schedule type="triggered"/>' if reader.triggered else '<schedule type="periodic" period="2"/>'
        activities.append((reader.place, f'<activity name="reading{index}">{schedule}'
                                         f'<components><component name="r{index}"/></components></activity>'))
    for place in sorted({place for place, _ in activities}):
        inside = "\n".join(f"    {text}" for where, text in activities if where == place)
        if place and processes:
            parts.append(f'    <process name="{place}">\n{inside}\n    </process>\n')
        else:
            parts.append(inside + "\n")
    parts.append("  </activities>\n</package>\n")
    return "".join(parts)


@dataclass
class Result:
    """What one run gave."""

    returncode: int
    output: str
    got: list[list[int]]
    """Per reader, the numbers it got."""
    old: list[int]
    bad: list[int]
    shm: list[int]
    """Per reader watching it, the launch's /dev/shm bytes once it had read everything."""
    rows: dict[str, list[int]]
    """Per connection label (``src.out -> r0.value``): written, read, dropped, pending."""
    pool: dict[str, str]
    """A frame source's pool at stop: ``slots`` and ``states``; its profile row's ``stalls``."""
    leftovers: list[str]


def launch(app: Path) -> subprocess.Popen[str]:
    env = dict(os.environ, PYTHONPATH=f"{DATA}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    return subprocess.Popen([sys.executable, "-m", "coco_core.launcher", str(app), "--profile", "1000"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)


def segments(launcher: int) -> list[str]:
    """The shared-memory segments of a launcher (their names start with its pid)."""
    return sorted(name for name in os.listdir("/dev/shm") if name.startswith(f"coco.{launcher}-"))


def run(case: Case, folder: Path, processes: bool, timeout: float = 60.0) -> Result:
    """Run ``case`` (in ``folder``) until every reader is done, then stop it with SIGINT. Raises
    AssertionError, with the launcher's output, when the readers are not done within ``timeout``."""
    folder.mkdir(parents=True, exist_ok=True)
    app = folder / "app.xml"
    app.write_text(xml(case, folder, processes))
    files = [folder / f"r{index}.txt" for index in range(len(case.readers))]
    launcher = launch(app)
    try:
        deadline = time.monotonic() + timeout
        while not all(path.exists() for path in files):
            if launcher.poll() is not None or time.monotonic() > deadline:
                break
            time.sleep(0.02)
        if launcher.poll() is None and not any(reader.die for reader in case.readers):
            os.killpg(launcher.pid, signal.SIGINT)  # a reader that kills its process stops the launch itself
        output, _ = launcher.communicate(timeout=30)
    finally:
        if launcher.poll() is None:
            os.killpg(launcher.pid, signal.SIGKILL)
            launcher.wait()
    missing = [path.name for path in files if not path.exists()]
    if missing:
        raise AssertionError(f"{case.describe()}: {', '.join(missing)} not done (processes={processes}):\n{output}")
    deadline = time.monotonic() + 2.0  # orphaned children sweep after the launcher's death
    while segments(launcher.pid) and time.monotonic() < deadline:
        time.sleep(0.02)
    result = Result(launcher.returncode, output, [], [], [], [], _rows(output), {}, segments(launcher.pid))
    for path in files:
        lines = path.read_text().splitlines()
        result.got.append([int(line) for line in lines if line.lstrip("-").isdigit()])
        fields = dict(line.split() for line in lines if not line.lstrip("-").isdigit())
        result.old.append(int(fields["old"]))
        result.bad.append(int(fields["bad"]))
        result.shm.append(int(fields["shm"]))
    pool = folder / "pool.txt"
    if pool.exists():
        result.pool = dict(line.split(" ", 1) for line in pool.read_text().splitlines())
        row = next((line for line in output.splitlines() if "src.frames" in line and "->" not in line), "")
        result.pool["row"] = row
    return result


def _rows(output: str) -> dict[str, list[int]]:
    rows = {}
    for line in output.splitlines():
        counters = re.search(r"(\d+)\s+(\d+)\s+(\d+)\s+(\d+)\s+(?:-|\S+ / \S+)$", line)  # then the age
        if " -> " in line and counters:
            words = line.split()
            arrow = words.index("->")
            rows[f"{words[arrow - 1]} -> {words[arrow + 1]}"] = [int(word) for word in counters.groups()]
    return rows


def problems(case: Case, result: Result) -> list[str]:
    """What in ``result`` breaks the rules every run of ``case`` keeps, whatever the timing."""
    found = []
    if result.returncode != 0 and not any(reader.die for reader in case.readers):
        found.append(f"exit status {result.returncode}")
    port = "frames" if case.policy == "POOL" else "out"
    for index, got in enumerate(result.got):
        label = f"src.{port} -> r{index}.value"
        if result.bad[index]:
            found.append(f"r{index}: {result.bad[index]} payloads differ from what was written")
        if got != sorted(set(got)) or any(not 0 <= number < case.count for number in got):
            found.append(f"r{index}: not increasing numbers of 0..{case.count - 1}: {got[:20]}...")
        if case.lossless(case.readers[index]) and got != list(range(case.count)):
            found.append(f"r{index}: lossless, yet got {len(got)} of {case.count}")
        if case.policy != "BUFFER" and (not got or got[-1] != case.count - 1):
            found.append(f"r{index}: the last value ({case.count - 1}) never arrived: {got[-5:]}")
        if case.policy == "POOL" and result.old[index]:
            found.append(f"r{index}: {result.old[index]} OLD_DATA reads of a pooled input")
        row = result.rows.get(label)
        if row is None:
            found.append(f"no profile row for {label}")
            continue
        written, read, dropped, pending = row
        if written != case.count or written != read + dropped + pending or pending:
            found.append(f"{label}: written/read/dropped/pending {row}, {case.count} written")
        if read != len(got):
            found.append(f"{label}: read {read}, the reader got {len(got)}")
    if case.policy == "POOL":
        states = result.pool.get("states", "").split()
        if any(state in ("reading", "writing") for state in states) or states.count("ready") > 1:
            found.append(f"slots left held at the end: {states}")
    if result.leftovers:
        found.append(f"segments left in /dev/shm: {result.leftovers}")
    return found


def differences(case: Case, alone: Result, spread: Result) -> list[str]:
    """Where the run over processes differs from the one-process run where it must not."""
    found = []
    for index, reader in enumerate(case.readers):
        if case.lossless(reader) and alone.got[index] != spread.got[index]:
            found.append(f"r{index} got other values than in one process")
    if alone.returncode != spread.returncode:
        found.append(f"exit status {spread.returncode}, {alone.returncode} in one process")
    if set(alone.rows) != set(spread.rows):
        found.append(f"profile rows {sorted(spread.rows)}, in one process {sorted(alone.rows)}")
    if alone.pool.get("slots") != spread.pool.get("slots"):
        found.append(f"pool slots {spread.pool.get('slots')}, {alone.pool.get('slots')} in one process")
    return found


def check(case: Case, folder: Path) -> tuple[Result, Result]:
    """Run ``case`` in one process and over processes; AssertionError listing every problem."""
    alone = run(case, folder / "alone", processes=False)
    spread = run(case, folder / "spread", processes=True)
    found = ([f"one process: {text}" for text in problems(case, alone)]
             + [f"processes: {text}" for text in problems(case, spread)] + differences(case, alone, spread))
    assert not found, f"{case.describe()}:\n  " + "\n  ".join(found) + f"\n{spread.output}"
    return alone, spread
