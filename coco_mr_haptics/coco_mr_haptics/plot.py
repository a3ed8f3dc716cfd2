"""haptic-plot: a haptic run at a glance, drawn from the CSV a HapticRecorder wrote.

    install/coco_mr_haptics/lib/coco_mr_haptics/haptic-plot out/haptics/haptic_implicit.csv [out.png]

Paths seen from the side (x-z) and from above (x-y), device thin and proxy thick, contacts coloured
by renderer; force magnitude and penetration over time, with the run's rate and energy in the title.
A separate command, not the recorder's ``on_stop``: drawing takes longer than an application may
take to stop.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from coco_core.errors import HapticDeviceError


def energy(table: np.ndarray) -> tuple[float, float]:
    """(in, out) of the contacts, as HapticRecorder counts them (force held over each step)."""
    force = np.stack([table["force_x"], table["force_y"], table["force_z"]], axis=1)[:-1]
    step = np.diff(np.stack([table["device_x"], table["device_y"], table["device_z"]], axis=1), axis=0)
    work = (force * step).sum(axis=1)
    return float(-work[work < 0].sum()), float(work[work > 0].sum())


def draw_run(csv_path: Path, png_path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    table = np.genfromtxt(csv_path, delimiter=",", names=True, dtype=None, encoding="utf-8")
    if table.size < 2:
        raise HapticDeviceError(f"{csv_path}: fewer than 2 haptic samples")
    t = table["time"] - table["time"][0]
    force = np.sqrt(table["force_x"] ** 2 + table["force_y"] ** 2 + table["force_z"] ** 2)
    figure, (side, top, forces) = plt.subplots(1, 3, figsize=(15, 4.2))
    renderers = sorted(set(table["renderer"].tolist()) - {""})
    for axis, (a, b) in ((side, ("x", "z")), (top, ("x", "y"))):
        axis.plot(table[f"device_{a}"], table[f"device_{b}"], color="0.6", lw=0.8, label="device")
        axis.plot(table[f"proxy_{a}"], table[f"proxy_{b}"], color="tab:blue", lw=1.6, label="proxy")
        for name in renderers:
            touching = table["renderer"] == name
            axis.scatter(table[f"proxy_{a}"][touching], table[f"proxy_{b}"][touching], s=2,
                         label=f"contact: {name}")
        axis.set_xlabel(f"{a} (m)")
        axis.set_ylabel(f"{b} (m)")
        axis.set_aspect("equal", adjustable="datalim")
    side.set_title("side view (render frame)")
    top.set_title("top view")
    side.legend(fontsize=7, loc="upper left")
    forces.plot(t, force, color="tab:red", lw=0.8, label="|force| (N)")
    forces.set_xlabel("time (s)")
    forces.set_ylabel("N")
    depth = forces.twinx()
    depth.plot(t, 1e3 * table["depth"], color="tab:green", lw=0.8, label="penetration (mm)")
    depth.set_ylabel("mm")
    absorbed, returned = energy(table)
    forces.set_title(f"{(len(t) - 1) / t[-1]:.0f} Hz, energy in {absorbed:.3f} J / out {returned:.3f} J")
    forces.legend(loc="upper left", fontsize=7)
    depth.legend(loc="upper right", fontsize=7)
    figure.tight_layout()
    png_path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(png_path, dpi=100)
    plt.close(figure)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="haptic-plot", description=__doc__.splitlines()[0])
    parser.add_argument("csv", type=Path, help="the CSV of a HapticRecorder")
    parser.add_argument("png", type=Path, nargs="?", help="the picture (default: the CSV's name with .png)")
    args = parser.parse_args(argv)
    png = args.png or args.csv.with_suffix(".png")
    try:
        draw_run(args.csv, png)
    except (OSError, ValueError) as error:
        print(f"haptic-plot: {error}", file=sys.stderr)
        return 1
    print(f"wrote {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
