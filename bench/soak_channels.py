"""Soak of the channels between processes: many generated applications, each run over processes and
in one process, compared (issue 27; the test suite runs a few of the same cases).

Each case draws from its seed a policy (DATA, BUFFER, CIRCULAR, POOL), a buffer size, a payload
(integers, int64 arrays, structured arrays with datetimes; frames of 64 B to 300 kB), a batch size,
one to three readers with their read mode (read, read_all, read_newest), trigger (event or periodic)
and held frames, and where the writer and each reader run (the launcher or one of three children).
``coco_core/test/data/channel_apps.py`` checks each run: every payload intact, numbers increasing,
every value for lossless readers and the same values as in one process, the last value for the
latest-value policies, the profile's written = read + dropped + pending with nothing pending, no
OLD_DATA from a pooled input, no slot left READING or WRITING, no segment left in /dev/shm.

    PYTHONPATH=coco_core .venv/bin/python bench/soak_channels.py --cases 200 --count 2000
    PYTHONPATH=coco_core .venv/bin/python bench/soak_channels.py --minutes 30

Exit status 1 when any case fails; the failing seeds are printed, to rerun with ``--seeds``.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
DATA = REPO / "coco_core" / "test" / "data"
for path in (DATA, REPO / "coco_core"):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))
# The launcher and its children run this checkout's coco_core too.
os.environ["PYTHONPATH"] = os.pathsep.join([str(REPO / "coco_core"), os.environ.get("PYTHONPATH", "")])

import channel_apps as apps  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="bench/soak_channels.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=50, help="generated applications to run (default 50)")
    parser.add_argument("--first-seed", type=int, default=1000, help="seed of the first case (default 1000)")
    parser.add_argument("--seeds", type=int, nargs="*", help="run exactly these seeds")
    parser.add_argument("--count", type=int, default=1000, help="values each writer writes (default 1000)")
    parser.add_argument("--minutes", type=float, help="stop starting cases after this long")
    options = parser.parse_args(argv)
    seeds = options.seeds or list(range(options.first_seed, options.first_seed + options.cases))
    started = time.monotonic()
    failed: list[int] = []
    ran = 0
    with tempfile.TemporaryDirectory(prefix="coco-soak-") as folder:
        for seed in seeds:
            if options.minutes is not None and time.monotonic() - started > options.minutes * 60:
                break
            case = apps.generate(seed, options.count)
            begun = time.monotonic()
            try:
                apps.check(case, Path(folder) / str(seed))
                verdict = "ok"
            except AssertionError as error:
                failed.append(seed)
                verdict = "FAILED\n" + "\n".join(f"    {line}" for line in str(error).splitlines()[:40])
            ran += 1
            print(f"seed {seed:6d}  {time.monotonic() - begun:5.1f} s  {case.describe()}  {verdict}", flush=True)
    print(f"\n{ran} cases in {time.monotonic() - started:.0f} s, {len(failed)} failed"
          + (f": --seeds {' '.join(map(str, failed))}" if failed else ""))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
