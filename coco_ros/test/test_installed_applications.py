"""Applications found from any folder (coco_core.applications), and the installed launch file.

Both launchers run as installed scripts from a folder that has no ``config/``: an installed
application by name, by ``package://`` URL and through ``$(find-pkg-share)``; the launch file
``share/coco_ros/launch/baxter_teleop_replay.launch.py`` parses, and the launcher accepts exactly the
command line launch_ros makes of its ``Node`` (executable, arguments, ``--ros-args``, ``-r
__node:=`` and ``__ns:=``, a ``--params-file`` keyed by the node's full name)."""

from __future__ import annotations

import ast
import os
import subprocess
from pathlib import Path
from typing import Any

import pytest
import yaml

WORKSPACE = Path(__file__).resolve().parents[2]
INSTALL = WORKSPACE / "install"
SHARE = INSTALL / "coco_ros" / "share" / "coco_ros"
LAUNCHER = INSTALL / "coco_ros" / "lib" / "coco_ros" / "launcher"
COCO_LAUNCH = INSTALL / "coco_core" / "lib" / "coco_core" / "coco-launch"


@pytest.fixture(autouse=True)
def installed() -> None:
    if not LAUNCHER.exists() or not SHARE.is_dir():
        pytest.skip("build the workspace first (scripts/setup.sh)")


def run(*words: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "ROS_DOMAIN_ID": "44", "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    return subprocess.run([*words], cwd=cwd, capture_output=True, text=True, timeout=60, env=env)


def test_config_is_installed_with_its_meshes_and_csvs() -> None:
    for name in ("baxter_teleop_replay.xml", "demo_pipeline.xml", "haptic_implicit.xml", "haptic_hand_stroke.csv",
                 "meshes/bowl.obj"):
        assert (SHARE / "config" / name).is_file(), name


@pytest.mark.parametrize("name", ["demo_pipeline", "demo_pipeline.xml", "package://coco_ros/config/demo_pipeline.xml"])
def test_an_installed_application_runs_by_name_from_any_folder(name: str, tmp_path: Path) -> None:
    for launcher in (LAUNCHER, COCO_LAUNCH):
        checked = run(str(launcher), name, "--check", cwd=tmp_path)
        assert checked.returncode == 0, checked.stderr
        assert "application demo_pipeline" in checked.stdout


def test_find_pkg_share_names_an_installed_application(tmp_path: Path) -> None:
    app = tmp_path / "mine.xml"
    app.write_text('<package name="mine"><includes><include>$(find-pkg-share coco_ros)/config/demo_pipeline.xml</include></includes></package>')
    checked = run(str(COCO_LAUNCH), str(app), "--check", cwd=tmp_path)
    assert checked.returncode == 0 and "activity acquisition" in checked.stdout, checked.stderr


def test_an_unknown_name_lists_the_installed_applications(tmp_path: Path) -> None:
    checked = run(str(LAUNCHER), "demo_pipelin", "--check", cwd=tmp_path)
    assert checked.returncode == 1
    assert "application 'demo_pipelin' not found" in checked.stderr
    assert ("installed applications: baxter_teleop_replay.xml, camera_registration.xml, composite_rgbd_meshes.xml, "
            "composite_signals.xml, demo_pipeline.xml") in checked.stderr
    wrong_url = run(str(LAUNCHER), "package://coco_ros/config/nothere.xml", "--check", cwd=tmp_path)
    assert wrong_url.returncode == 1 and "config/nothere.xml does not exist" in wrong_url.stderr


def _literal(node: ast.expr, launch_arguments: dict[str, str]) -> Any:
    """The value of a launch file's expression, LaunchConfiguration('x') being x's default."""
    if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "LaunchConfiguration":
        return launch_arguments[ast.literal_eval(node.args[0])]
    if isinstance(node, ast.List):
        return [_literal(item, launch_arguments) for item in node.elts]
    if isinstance(node, ast.Dict):
        return {ast.literal_eval(k): _literal(v, launch_arguments) for k, v in zip(node.keys, node.values)}  # type: ignore[arg-type]
    return ast.literal_eval(node)


def launch_ros_command(launch_file: Path, params_file: Path, overrides: dict[str, str]) -> list[str]:
    """The command launch_ros runs for the launch file's one ``Node`` (launch_ros/actions/node.py:
    executable, arguments, then ``--ros-args -r __node:=NAME -r __ns:=/NS --params-file FILE``, the
    file keyed by the node's full name), with the launch arguments at their defaults but ``overrides``."""
    tree = ast.parse(launch_file.read_text(), str(launch_file))
    calls = [node for node in ast.walk(tree) if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)]
    defaults = {ast.literal_eval(call.args[0]): ast.literal_eval(next(k.value for k in call.keywords if k.arg == "default_value"))
                for call in calls if call.func.id == "DeclareLaunchArgument"}  # type: ignore[attr-defined]
    defaults.update(overrides)
    (node,) = [call for call in calls if call.func.id == "Node"]  # type: ignore[attr-defined]
    kwargs = {keyword.arg: _literal(keyword.value, defaults) for keyword in node.keywords}
    assert kwargs["package"] == "coco_ros" and kwargs["executable"] == "launcher"
    full_name = f"/{kwargs['namespace']}/{kwargs['name']}"
    params: dict[str, Any] = {}
    for entry in kwargs["parameters"]:
        params.update(entry)
    params_file.write_text(yaml.dump({full_name: {"ros__parameters": params}}, default_flow_style=False))
    return [str(LAUNCHER), *kwargs["arguments"], "--ros-args", "-r", f"__node:={kwargs['name']}",
            "-r", f"__ns:=/{kwargs['namespace']}", "--params-file", str(params_file)]


def test_the_launch_file_parses_and_its_node_command_line_reaches_the_application(tmp_path: Path) -> None:
    launch_file = SHARE / "launch" / "baxter_teleop_replay.launch.py"
    compile(launch_file.read_text(), str(launch_file), "exec")
    command = launch_ros_command(launch_file, tmp_path / "launch_params_x", {"bag": "no/such/bag", "display": "false"})
    result = run(*command, cwd=tmp_path)
    # The launch argument went through the params file into the application's <arg>: its bag is looked for.
    assert result.returncode == 1, result.stdout + result.stderr
    assert "no/such/bag: no such bag" in result.stderr, result.stderr
    assert "1 error in the application" in result.stderr, result.stderr
