"""scripts/setup.sh points the rosidl wheels' CMake exports at this venv's headers inside the venv.

The wheels' exported CMake targets name the include directories of the machine that built them
(``/opt/python/cpXY-cpXY/...``). Set-up must rewrite those paths in the venv's own files, never
create them on the machine (that needed root and was shared by every workspace).
"""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy
import pytest

from conftest import ROOT

VENV = ROOT / ".venv"
BUILDER_PATHS = ("/opt/python/cp311-cp311/include/python3.11;"
                 "/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include")


def run_rewrite(venv: Path) -> subprocess.CompletedProcess[str]:
    """Run setup.sh's ``ensure_wheel_build_paths`` alone on ``venv`` (the function, not the script)."""
    script = (f'set -euo pipefail; VENV="{venv}"; log() {{ printf "[setup] %s\\n" "$*" >&2; }}\n'
              f"source <(sed -n '/^ensure_wheel_build_paths() {{/,/^}}/p' '{ROOT / 'scripts' / 'setup.sh'}')\n"
              "ensure_wheel_build_paths")
    return subprocess.run(["bash", "-c", script], capture_output=True, text=True, timeout=60)


def test_the_rewrite_points_the_exports_at_this_interpreter_and_touches_nothing_else(tmp_path):
    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    python = venv / "bin" / "python"  # this interpreter, run as the venv's (its numpy is the one expected)
    python.write_text(f'#!/bin/sh\nexec "{sys.executable}" "$@"\n')
    python.chmod(0o755)
    export = venv / "share" / "geometry_msgs" / "cmake" / "export_geometry_msgs__rosidl_generator_pyExport.cmake"
    export.parent.mkdir(parents=True)
    export.write_text(f'set_target_properties(x PROPERTIES\n  INTERFACE_INCLUDE_DIRECTORIES "{BUILDER_PATHS}"\n)\n')
    other = venv / "share" / "geometry_msgs" / "package.xml"
    other.write_text("<package>/opt/python/cp311-cp311 is not a CMake file</package>\n")
    before = {path: path.stat().st_mtime_ns for path in tmp_path.rglob("*") if path.is_file()}

    done = run_rewrite(venv)
    assert done.returncode == 0, done.stderr
    expected = f"{sysconfig.get_paths()['include']};{numpy.get_include()}"
    assert f'INTERFACE_INCLUDE_DIRECTORIES "{expected}"' in export.read_text()
    assert "/opt/python" in other.read_text()
    changed = [path for path, mtime in before.items() if path.stat().st_mtime_ns != mtime]
    assert changed == [export]
    # Again: nothing left to rewrite, nothing written.
    done = run_rewrite(venv)
    assert done.returncode == 0 and "pointing" not in done.stderr, done.stderr


def test_this_workspace_venv_exports_name_its_own_headers():
    if not VENV.is_dir():
        pytest.fail(f"{VENV} is missing: run scripts/setup.sh first")
    exports = sorted((VENV / "share").glob("*/cmake/*rosidl_generator_pyExport.cmake"))
    assert exports, "no rosidl Python export files in the venv"
    left = [str(path) for path in exports if "/opt/python/" in path.read_text()]
    assert not left, f"export files still naming the wheel builder's paths: {left}"
    numpy_include = subprocess.run([str(VENV / "bin" / "python"), "-c", "import numpy; print(numpy.get_include())"],
                                   capture_output=True, text=True, check=True).stdout.strip()
    assert numpy_include in exports[0].read_text()
    assert os.path.isdir(numpy_include)

