"""Every shell command the documentation shows runs as written, after the README's own steps.

The commands are read from the Markdown itself (every line of every ```bash / ```sh block of
README.md and docs/*.md), so a command added to the docs is covered without touching this file.

How a documented line is run (the rules a reader of a failure needs):

- in a fresh ``bash`` started in the workspace root, with the environment of a new terminal (no
  virtual environment, no workspace on PATH, PYTHONPATH, AMENT_PREFIX_PATH...), after the README's
  step ``source install/setup.bash`` and after the ``source ...`` lines above it in its own block;
  the lines of one block run in order (a later line may use what an earlier one made);
- a line that runs an application until it is stopped (``coco-launch`` / ``launcher`` with an
  application file and without ``--check`` / ``--list``, or ``scripts/run_app.sh``) gets
  ``--duration 4`` (``APP_SECONDS``): right after the file for a launcher (before ``--ros-args``),
  in place of a documented ``--duration``, at the end for run_app.sh, which hands its arguments to
  the launcher (the launcher takes the last ``--duration``); an application that ends by itself
  (``RUN_TO_ITS_END``) runs to its end instead;
- an output the line names under ``out/`` (e.g. ``out/shake_hand``) is made by it: one left by an
  earlier run is moved aside for the block and put back afterwards (a bag is never overwritten);
- it must exit with status 0 within ``TIMEOUT`` seconds;
- the blocks run once per test session, side by side (``documented_runs``): they mostly wait on
  applications that run for seconds. When a block builds the workspace (``scripts/setup.sh``, also
  sourced by run_app.sh), ``scripts/setup.sh`` runs first and alone, as the blocks run what it
  installs; the blocks then all run side by side, their own setup.sh finding the workspace up to date
  (it then writes nothing; should that first setup fail, the blocks that build run first and alone). Blocks that name the same application file or ``out/`` path run one
  after the other in one worker (an application's default outputs are the same in both); the
  longest groups start first (``expected_seconds``); each block has a ROS domain of its own;
- the lines in ``NOT_RUN`` are not run, each for the reason given there (a test checks the list
  names only lines the docs still show, so it cannot rot), nor are lines that run a benchmark script
  (``bench/*.py``: see ``not_run_reason``).
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from conftest import ROOT

APP_SECONDS = 4
TIMEOUT = 300
SHELLS = {"bash", "sh"}
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

NOT_RUN: dict[str, str] = {
    "./scripts/run_tests.sh":
        "runs the whole test suite, this test included (it would run itself); the suite run is how it is exercised",
    "./scripts/run_app.sh palpation":
        "test/test_palpation_app.py runs this very line (with the test's shorter session, the hand at half speed and "
        "its own outputs) and checks what it prints and writes; that test runs alone after the other suites, since "
        "the application's five processes need both cores (here, with the other suites beside it, the remote camera "
        "delivered 21 of 255 frames and the calibration touch was never seen)",
    "coco-launch config/camera_registration.xml record:=out/registration_bag":
        "test/test_camera_registration_app.py runs this very line (read from docs/vision.md, with its own outputs: "
        "the recording and output:=) and checks the registration against the goal; it runs to its end (20-30 s of "
        "rendering and marker detection at 1280x960 on both cores), so it is not run a second time here",
    "coco-launch config/camera_registration.xml source:=bag bag:=out/registration_bag truth:=true "
    "output:=out/registration_from_bag":
        "test/test_camera_registration_app.py runs this very line (read from docs/vision.md) on the recording the "
        "line above made there, with its own output, and checks the registration against the goal and the "
        "simulated run's",
    "ros2 run coco_ros launcher config/demo_pipeline.xml":
        "needs the ros2 command line (ros2cli), which the PyPI wheels here do not include; the line above runs the "
        "same installed script by its path",
    "coco-launch config/hosts_demo_pipeline.xml --host sensor --key out/app.key":
        "one host of an application over two: it waits for the other host, started at the same time on another "
        "machine; test/test_hosts_netns.py runs this file with --host sensor and --host station side by side, each "
        "in a network namespace of its own, with a key coco-keygen made, and checks both",
    "coco-launch config/hosts_demo_pipeline.xml --host station --key out/app.key":
        "the other host of the line above (test/test_hosts_netns.py runs both at once)",
    "ros2 run coco_ros launcher config/hosts_demo_pipeline.xml --host station --key out/app.key":
        "needs the ros2 command line (ros2cli), which the PyPI wheels here do not include, and the other host; "
        "test/test_hosts_netns.py runs the installed ROS launcher as one of two hosts",
}

RUN_TO_ITS_END: dict[str, str] = {
    "config/camera_registration.xml":
        "stops by itself once the camera is registered (about 10 s); cut short, it registers nothing and exits 1, "
        "as it should",
}

BENCHMARK = re.compile(r"\bbench/\w+\.py\b")
"""A line that runs a benchmark script is not run either: benchmarks load the machine for minutes and
rewrite bench/results and docs/img; they are run by hand, never as tests."""


def not_run_reason(bare: str) -> str | None:
    """Why a documented line is not run by this test; None when it is run."""
    if bare in NOT_RUN:
        return NOT_RUN[bare]
    if BENCHMARK.search(bare):
        return "a benchmark: run by hand (minutes of load, it rewrites bench/results and docs/img), never as a test"
    return None


LAUNCHERS = {"coco-launch", "launcher"}
ENVIRONMENT = re.compile(r"((?:[A-Za-z_][A-Za-z0-9_]*=\S*\s+)*)(.*)", re.S)
"""A command line: its leading environment assignments (raw), and the rest."""


@dataclass
class Command:
    """One documented command line and where it is written."""

    path: Path
    line: int
    text: str

    @property
    def where(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"

    @property
    def bare(self) -> str:
        """The line without its trailing comment (the key of ``NOT_RUN``)."""
        return re.sub(r"\s+#\s.*$", "", self.text).strip()


@dataclass
class Block:
    """A fenced shell block: its commands, run in order in one test."""

    path: Path
    line: int
    commands: list[Command] = field(default_factory=list)


def shell_blocks(path: Path) -> list[Block]:
    """The ```bash / ```sh blocks of a Markdown file; continued lines (``\\``) are joined."""
    blocks: list[Block] = []
    current: Block | None = None
    pending: tuple[int, str] | None = None
    for number, raw in enumerate(path.read_text().splitlines(), start=1):
        fence = re.match(r"^\s*```\s*([\w+-]*)", raw)
        if fence:
            if current is None:
                current = Block(path, number) if fence.group(1) in SHELLS else Block(path, -number)
            else:
                if current.line > 0:
                    blocks.append(current)
                current = None
            continue
        if current is None or current.line < 0:
            continue
        start, text = pending if pending else (number, "")
        text = f"{text} {raw.strip()}" if text else raw.strip()
        if text.endswith("\\"):
            pending = (start, text[:-1].rstrip())
            continue
        pending = None
        if text and not text.startswith("#"):
            current.commands.append(Command(path, start, text))
    return blocks


def all_blocks() -> list[Block]:
    return [block for path in DOCS for block in shell_blocks(path)]


def fresh_terminal_env() -> dict[str, str]:
    """The environment of a new terminal: nothing of this workspace or its venv on any search path."""
    env = {key: value for key, value in os.environ.items()
           if key not in {"VIRTUAL_ENV", "PYTHONPATH", "AMENT_PREFIX_PATH", "CMAKE_PREFIX_PATH",
                          "COLCON_PREFIX_PATH", "PYTHONHOME", "VIRTUAL_ENV_PROMPT"}
           # _ROS_WHEELS_BOOTSTRAP_COMPLETE: the ROS wheels' start-up already set LD_LIBRARY_PATH in the
           # venv's interpreter that runs this test; a new terminal has not.
           and not key.startswith(("COLCON_", "_ROS_"))}
    root = str(ROOT)
    for key in ("PATH", "LD_LIBRARY_PATH"):
        if key in env:
            env[key] = os.pathsep.join(entry for entry in env[key].split(os.pathsep)
                                       if entry and not entry.startswith(root))
    env.update(ROS_DOMAIN_ID="83", ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")
    return env


def shortened(command: str) -> str:
    """The command with ``--duration APP_SECONDS`` where it runs an application (module docstring).
    Leading ``NAME=value`` words (``PYTHONPATH=$PWD/...:$PYTHONPATH launcher ...``) are kept as
    written, for the shell to expand."""
    assignments, bare = ENVIRONMENT.match(re.sub(r"\s+#\s.*$", "", command).strip()).groups()  # type: ignore[union-attr]  # always matches
    words = shlex.split(bare)
    program = Path(words[0]).name if words else ""
    if program == "run_app.sh":
        return f"{assignments}{bare} --duration {APP_SECONDS}"
    if program in LAUNCHERS and not {"--check", "--list"} & set(words):
        files = [i for i, word in enumerate(words) if word.endswith(".xml")]
        if files and words[files[0]] not in RUN_TO_ITS_END:
            # A documented --duration (before --ros-args, where the launcher reads its own options) is
            # replaced: the launcher takes the last one, and a longer one would outlast APP_SECONDS.
            end = words.index("--ros-args") if "--ros-args" in words else len(words)
            kept = [word for i, word in enumerate(words[:end])
                    if word != "--duration" and (i == 0 or words[i - 1] != "--duration")]
            at = kept.index(words[files[0]]) + 1
            return assignments + shlex.join([*kept[:at], "--duration", str(APP_SECONDS), *kept[at:], *words[end:]])
    return command


def test_the_docs_show_commands_and_the_extraction_finds_them() -> None:
    """A sanity check of the extraction itself: the README's own commands are among those found."""
    commands = [command.bare for block in all_blocks() for command in block.commands]
    assert "source install/setup.bash" in commands
    assert any(command.startswith("coco-launch config/demo_pipeline.xml") for command in commands)
    assert any(command.startswith("baxter-import") for command in commands)


def test_every_line_not_run_is_still_documented() -> None:
    documented = {command.bare for block in all_blocks() for command in block.commands}
    stale = sorted(set(NOT_RUN) - documented)
    assert not stale, f"NOT_RUN names lines the docs no longer show: {stale}"


def test_shortened_inserts_the_duration_after_the_application_file() -> None:
    assert shortened("launcher config/a.xml x:=1 --ros-args -p a:=1") == \
        f"launcher config/a.xml --duration {APP_SECONDS} x:=1 --ros-args -p a:=1"
    assert shortened("coco-launch config/a.xml --check   # comment") == "coco-launch config/a.xml --check   # comment"
    assert shortened("./scripts/run_app.sh   # main job") == f"./scripts/run_app.sh --duration {APP_SECONDS}"
    assert shortened("coco-launch config/camera_registration.xml source:=bag") == \
        "coco-launch config/camera_registration.xml source:=bag"
    # A documented duration gives way to APP_SECONDS (the launcher takes the last one).
    assert shortened("coco-launch config/a.xml window:=16 --duration 10 --profile 2") == \
        f"coco-launch config/a.xml --duration {APP_SECONDS} window:=16 --profile 2"
    assert shortened("launcher config/a.xml --duration 3 --ros-args -p duration:=9") == \
        f"launcher config/a.xml --duration {APP_SECONDS} --ros-args -p duration:=9"
    # Environment assignments before the launcher stay as written, for the shell to expand.
    assert shortened("PYTHONPATH=$PWD/x:$PYTHONPATH launcher x/a.xml g:=3 --ros-args -r __ns:=/lab") == \
        f"PYTHONPATH=$PWD/x:$PYTHONPATH launcher x/a.xml --duration {APP_SECONDS} g:=3 --ros-args -r __ns:=/lab"


BUILDS = re.compile(r"\bscripts/(setup|run_app)\.sh\b")
"""A line that builds the workspace (run_app.sh sources setup.sh): scripts/setup.sh runs before the blocks."""
WORKERS = 3
"""Blocks run side by side: on a 2-core machine they mostly wait on applications that run for seconds
(the whole test used about half a core), so three at a time keep one core busy, not more."""
DOMAIN_BASE = 120
"""Block i runs on ROS domain DOMAIN_BASE + i: launchers of two blocks never see each other's topics."""


@dataclass
class BlockRun:
    """What running one block gave: the failures, how many lines ran, and the lines not run (why)."""

    failures: list[str] = field(default_factory=list)
    ran: int = 0
    log: list[str] = field(default_factory=list)


def block_id(block: Block) -> str:
    return f"{block.path.relative_to(ROOT)}:{block.line}"


def out_paths(block: Block) -> list[Path]:
    """The ``out/...`` paths the block's lines name (their outputs, moved aside while the blocks run)."""
    paths = []
    for command in block.commands:
        for word in shlex.split(command.bare):
            path = ROOT / word.partition(":=")[2 if ":=" in word else 0]
            if path.is_relative_to(ROOT / "out") and path != ROOT / "out":
                paths.append(path)
    return paths


RUN_APP_FILES = {"palpation": "config/palpation_replay.xml", "": "config/baxter_teleop_replay.xml"}
"""The application file ``scripts/run_app.sh [palpation]`` runs (with its default outputs, which a
block running that file without ``output:=`` writes too)."""


def resources(block: Block) -> set[str]:
    """What two blocks must not use at the same time: the application files (those run_app.sh runs
    too) and ``out/`` paths named."""
    words = {word.partition(":=")[2] or word for command in block.commands for word in shlex.split(command.bare)}
    for command in block.commands:
        run_app = shlex.split(command.bare)
        if run_app and Path(run_app[0]).name == "run_app.sh":
            words.add(RUN_APP_FILES["palpation" if run_app[1:2] == ["palpation"] else ""])
    return {word for word in words if word.endswith(".xml")} | {str(path) for path in out_paths(block)}


def chains(blocks: list[Block]) -> list[list[Block]]:
    """The blocks grouped so that blocks sharing a resource (transitively) are in one group, in order."""
    groups: list[tuple[set[str], list[Block]]] = []
    for block in blocks:
        used = resources(block)
        joined = [group for group in groups if group[0] & used]
        merged: tuple[set[str], list[Block]] = (used, [])
        for group in joined:
            merged[0].update(group[0])
            merged[1].extend(group[1])
            groups.remove(group)
        merged[1].append(block)
        merged[1].sort(key=blocks.index)
        groups.append(merged)
    return [group[1] for group in groups]


def expected_seconds(chain: list[Block]) -> float:
    """About how long a group of blocks runs (seconds): the groups start longest first, so that the
    longest is not the last one started while the other workers sit idle (it is the run's length).
    An application run to its end takes ~20 s (camera_registration.xml: 20-30 s), run_app.sh builds,
    may generate its session and runs its application (~20 s), an application cut to APP_SECONDS
    takes that and ~2 s to start; any other line ~1 s."""
    def seconds(command: Command) -> float:
        if not_run_reason(command.bare) is not None:
            return 0.0
        if any(name in command.bare for name in RUN_TO_ITS_END):
            return 20.0
        if "run_app.sh" in command.bare:
            return 20.0
        if shortened(command.text) != command.text or "--duration" in command.bare:
            return APP_SECONDS + 2.0
        return 1.0
    return sum(seconds(command) for block in chain for command in block.commands)


def run_block(block: Block, domain: int) -> BlockRun:
    """Run a block's lines in order (the module docstring's rules), each in a fresh bash."""
    env = {**fresh_terminal_env(), "ROS_DOMAIN_ID": str(domain)}
    sourced: list[str] = []
    result = BlockRun()
    for command in block.commands:
        reason = not_run_reason(command.bare)
        if reason is not None:
            result.log.append(f"not run: {command.where}: {command.bare} ({reason})")
            continue
        script = "\n".join(["source install/setup.bash", *sourced, shortened(command.text)])
        try:
            done = subprocess.run(["bash", "-c", script], cwd=ROOT, env=env, capture_output=True, text=True,
                                  timeout=TIMEOUT)
        except subprocess.TimeoutExpired as error:
            result.failures.append(f"{command.where}: `{command.text}` did not finish within {TIMEOUT} s:\n"
                                   f"{error.stdout}")
            continue
        result.ran += 1
        if done.returncode != 0:
            result.failures.append(f"{command.where}: `{command.text}` exited with {done.returncode}:\n"
                                   f"{done.stdout[-3000:]}\n{done.stderr[-3000:]}")
        if command.bare.startswith("source "):
            sourced.append(command.bare)
    return result


@pytest.fixture(scope="session")
def documented_runs(request: pytest.FixtureRequest):
    """Every block whose test is selected, run once (module docstring), by block id; the ``out/...``
    paths they name are moved aside for the run and put back afterwards."""
    selected = {block_id(item.callspec.params["block"]) for item in request.session.items
                if getattr(item, "originalname", "") == "test_documented_block_runs_as_written"}
    blocks = [block for block in all_blocks() if block_id(block) in selected]
    moved: list[tuple[Path, Path]] = []
    for path in dict.fromkeys(path for block in blocks for path in out_paths(block)):
        if path.exists():
            aside = path.with_name(f".{path.name}.before-test")
            shutil.rmtree(aside, ignore_errors=True)
            path.rename(aside)
            moved.append((path, aside))
    domains = {block_id(block): DOMAIN_BASE + i for i, block in enumerate(all_blocks())}
    runs: dict[str, BlockRun] = {}

    def run_chain(chain: list[Block]) -> None:
        for block in chain:
            runs[block_id(block)] = run_block(block, domains[block_id(block)])

    try:
        builders = [block for block in blocks if any(BUILDS.search(c.bare) and not not_run_reason(c.bare)
                                                      for c in block.commands)]
        if builders:
            # The build the blocks' setup.sh would make, once, before any block runs what it installs.
            # Should it fail, the blocks that build run first and alone, as they would build each time
            # (two builds at once would share build/): their own lines then show the failure.
            prepared = subprocess.run(["bash", "-c", "source scripts/setup.sh"], cwd=ROOT, env=fresh_terminal_env(),
                                      capture_output=True, text=True, timeout=TIMEOUT)
            if prepared.returncode == 0:
                builders = []
        for block in builders:
            run_chain([block])
        with ThreadPoolExecutor(WORKERS) as pool:
            list(pool.map(run_chain, sorted(chains([block for block in blocks if block not in builders]),
                                            key=expected_seconds, reverse=True)))
        yield runs
    finally:
        for path, aside in moved:
            shutil.rmtree(path, ignore_errors=True)
            aside.rename(path)


def test_blocks_that_share_an_application_or_output_run_in_one_chain() -> None:
    a, b, c, d = (Block(ROOT / "README.md", line) for line in (1, 2, 3, 4))
    a.commands.append(Command(a.path, 1, "coco-launch config/x.xml"))
    b.commands.append(Command(b.path, 2, "coco-launch config/y.xml output:=out/y"))
    c.commands.append(Command(c.path, 3, "launcher config/x.xml --ros-args -r __node:=n"))
    d.commands.append(Command(d.path, 4, "baxter-import a.dat out/y"))
    assert chains([a, b, c, d]) == [[a, c], [b, d]]
    # run_app.sh runs the Baxter replay (its outputs the file's defaults): with a block that runs that file.
    e, f, g = (Block(ROOT / "README.md", line) for line in (5, 6, 7))
    e.commands.append(Command(e.path, 5, "./scripts/run_app.sh   # main job"))
    f.commands.append(Command(f.path, 6, "coco-launch config/baxter_teleop_replay.xml bag:=out/b"))
    g.commands.append(Command(g.path, 7, "./scripts/run_app.sh palpation"))
    assert chains([e, g, f]) == [[g], [e, f]]


def test_the_longest_groups_start_first() -> None:
    """The group that runs longest would otherwise start last and outlast the others by its length."""
    quick, to_its_end = (Block(ROOT / "README.md", line) for line in (1, 2))
    quick.commands.append(Command(quick.path, 1, "coco-launch config/x.xml --check"))
    to_its_end.commands.append(Command(to_its_end.path, 2, "coco-launch config/camera_registration.xml"))
    assert sorted([[quick], [to_its_end]], key=expected_seconds, reverse=True) == [[to_its_end], [quick]]


@pytest.mark.timeout(3 * TIMEOUT)  # the first block's test waits for every block (they run side by side)
@pytest.mark.parametrize("block", all_blocks(), ids=block_id)
def test_documented_block_runs_as_written(block: Block, documented_runs: dict[str, BlockRun]) -> None:
    run = documented_runs[block_id(block)]
    print("\n".join(run.log))
    assert not run.failures, "\n\n".join(run.failures)
    if not run.ran:
        pytest.skip("no line of this block is run here (reasons printed above)")
