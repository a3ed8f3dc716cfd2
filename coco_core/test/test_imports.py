"""What importing the runtime loads: only what is used (a launcher installs its signal handling
before the runtime loads; the diagnostics server's http.server is a fifth of the import time)."""

from __future__ import annotations

import subprocess
import sys


def loaded_after(statement: str) -> set[str]:
    script = f"import sys\n{statement}\nprint(' '.join(sorted(sys.modules)))"
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    return set(result.stdout.split())


def test_importing_coco_core_loads_nothing_of_the_runtime() -> None:
    modules = loaded_after("import coco_core")
    assert not {"numpy", "coco_core.application", "coco_core.transforms"} & modules


def test_the_diagnostics_server_is_imported_only_when_served() -> None:
    modules = loaded_after("import coco_core.application, coco_core.component, coco_core.transforms")
    assert "http.server" not in modules and "socketserver" not in modules
    assert "http.server" in loaded_after("from coco_core.transforms import TransformServer")


def test_public_names_still_import_from_the_package() -> None:
    modules = loaded_after("from coco_core import Application, Component, Stamped, InputPort")
    assert "coco_core.application" in modules
