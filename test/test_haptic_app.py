"""The haptic application file (config/haptic_implicit.xml) run through the installed ``coco-launch``:
a simulated device strokes a CSG scene at 1 kHz, and what it writes is checked against the scene."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import pytest

from conftest import read_rows, run_launcher

from coco_core.builder import build_application
from coco_core.errors import ConfigErrors
from coco_core.xml.loader import parse_application_string
from coco_mr_haptics.expression import parse_surface
from coco_mr_haptics.scene import Scene

APP = "config/haptic_implicit.xml"


def test_haptic_app_runs_the_device_against_the_scene(coco_launch: Path, tmp_path: Path) -> None:
    result = run_launcher(coco_launch, APP, f"out:={tmp_path}", "--profile", "100")
    assert result.returncode == 0, result.stderr
    assert "the hand trajectory is over" in result.stderr
    summary = json.loads((tmp_path / "haptic_implicit_summary.json").read_text())
    rows = read_rows(tmp_path / "haptic_implicit.csv")
    # A 7 s trajectory at 1 kHz: 7,000 cycles on a quiet machine; a loaded one skips missed deadlines
    # (3,800-4,600 samples were seen at load 8-10), so the rate itself is bench_haptics.py's to measure.
    assert summary["samples"] == len(rows) > 2000
    assert summary["rate_hz"] > 500
    assert summary["passive"] and summary["energy_in_j"] > 0
    assert set(summary["contacts_by_renderer"]) == {"scene", "ball"}
    assert 0.001 < summary["max_penetration_m"] < 0.02
    # Every proxy of the scene's renderer is on or outside the scene, never inside it.
    text = re.search(r'name="surface" value="(union\(difference.*?)"/>', Path(APP).read_text()).group(1)
    scene = Scene(parse_surface(text))
    proxies = np.array([[float(r[f"proxy_{a}"]) for a in "xyz"] for r in rows if r["renderer"] == "scene"])
    assert len(proxies) > 1000
    assert scene.distance(proxies).min() > -1e-6
    # The thin wall was pushed: on its face the force points away from it (-x) or is zero (a surface
    # never pulls: damping of a withdrawing hand cannot make it attractive).
    wall = [float(r["force_x"]) for r in rows if r["renderer"] == "scene" and abs(float(r["proxy_x"]) + 0.061) < 1e-6]
    assert len(wall) > 50 and max(wall) <= 0.0 and min(wall) < -0.3


def test_surface_typo_is_reported_at_its_line_and_column() -> None:
    text = Path(APP).read_text().replace("sphere(0.02)", "sphre(0.02)")
    line = next(i for i, row in enumerate(text.splitlines(), start=1) if "sphre(0.02)" in row)
    try:
        build_application(parse_application_string(text, "haptic.xml"), "haptics")  # the process with the scene
    except ConfigErrors as error:
        message = str(error)
    else:
        raise AssertionError("a typo in the surface was accepted")
    assert f"haptic.xml:{line}" in message
    assert "unknown surface function 'sphre'; did you mean 'sphere'?" in message
    assert "column 15" in message  # frame('ball', sphre(...): the 15th character


@pytest.mark.parametrize("original,hostile,words", [
    ("sphere(0.02)", "sphere(1e999)", ["number 1e999 is out of range", "column 22"]),
    ("frame('ball', sphere(0.02))", "frame('ball', translate([1e999, 0, 0], sphere(0.02)))",
     ["number 1e999 is out of range", "column 26"]),
    ("frame('ball', sphere(0.02))", "union(" * 495 + "sphere(0.02)" + ")" * 495,
     ["nests deeper than 64 calls"]),
])
def test_absurd_numbers_and_deep_nesting_are_refused_at_their_line(original: str, hostile: str,
                                                                   words: list[str]) -> None:
    """What made every haptic cycle NaN, or a RecursionError traceback, is refused when the file loads."""
    text = Path(APP).read_text().replace(original, hostile)
    line = next(i for i, row in enumerate(text.splitlines(), start=1) if hostile in row)
    with pytest.raises(ConfigErrors) as caught:
        build_application(parse_application_string(text, "haptic.xml"), "haptics")  # the process with the scene
    message = str(caught.value)
    assert f"haptic.xml:{line}" in message
    for word in words:
        assert word in message


def _not_a_trajectory(kind: str, folder: Path) -> str:
    """A name the trajectory attribute must refuse: what the probe gave ``--check``."""
    if kind == "device":
        return "/dev/zero"
    if kind == "folder":
        return str(folder)
    path = folder / kind
    if kind == "fifo":
        os.mkfifo(path)
    else:  # a 2 GB file, sparse: no disk is used
        with open(path, "wb") as file:
            file.truncate(2 << 30)
    return str(path)


@pytest.mark.parametrize("kind,words", [
    ("device", "is a character device, not a regular file"),
    ("fifo", "is a FIFO, not a regular file"),
    ("folder", "is a directory, not a regular file"),
    ("huge", "has 2147483648 bytes, more than the limit of"),
])
def test_a_trajectory_that_is_no_regular_file_is_refused_when_the_file_loads(tmp_path: Path, kind: str,
                                                                              words: str) -> None:
    """``--check`` builds the application as the run does: it finds what the device's ``on_config``
    would refuse (the run went on without its device until killed)."""
    spec = parse_application_string(Path(APP).read_text(), "haptic.xml", {"trajectory": _not_a_trajectory(kind, tmp_path)})
    line = next(i for i, row in enumerate(Path(APP).read_text().splitlines(), 1) if '<attribute name="trajectory"' in row)
    with pytest.raises(ConfigErrors) as caught:
        build_application(spec, "haptics")  # the process with the device
    message = str(caught.value)
    assert f"haptic.xml:{line}" in message and "device.trajectory (file)" in message, message
    assert words in message and "expected a CSV file time,x,y,z[,buttons]" in message, message


def test_check_refuses_dev_zero_as_the_trajectory(coco_launch: Path) -> None:
    result = run_launcher(coco_launch, APP, "--check", "trajectory:=/dev/zero")
    assert result.returncode == 1, result.stdout + result.stderr
    assert "/dev/zero is a character device, not a regular file" in result.stderr


@pytest.mark.parametrize("arg,value,attribute", [
    ("stiffness", "nan", "scene.stiffness"),  # 40 % of cycles faulted to zero force, exit 0
    ("stiffness", "1e999", "scene.stiffness"),
    ("friction", "nan", "scene.static_friction"),  # a ZeroDivisionError in the renderer, exit 0
])
def test_a_non_finite_material_is_refused_at_its_line(arg: str, value: str, attribute: str) -> None:
    text = Path(APP).read_text()
    name = attribute.split(".")[1]
    line = next(i for i, row in enumerate(text.splitlines(), 1) if f'name="{name}" value="$(arg {arg})"' in row)
    with pytest.raises(ConfigErrors) as caught:
        build_application(parse_application_string(text, "haptic.xml", {arg: value}), "haptics")
    message = str(caught.value)
    assert f"haptic.xml:{line}: attribute {attribute} (float): expected a finite number" in message, message
