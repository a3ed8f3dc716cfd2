"""Bad input to ``coco-launch``: clear errors with file:line, and nothing starts."""

from __future__ import annotations

import re

from pathlib import Path

import pytest

from conftest import DEMO_APP, SHARED_DATA, run_launcher

BROKEN_CONNECTION = """<package>
  <components>
    <component><name>gen</name><task>SignalGenerator</task><library>coco_core</library>
      <attributes><attribute name="frequency" value="fast"/></attributes>
    </component>
    <component><name>rec</name><task>CsvRecorder</task><library>coco_core</library>
      <attributes><attribute name="path" value="{out}"/></attributes>
    </component>
  </components>
  <connections>
    <connection data="DATA" policy="LOCKED">
      <src task="gen" port="sampel"/>
      <dest task="rec" port="values"/>
    </connection>
  </connections>
  <activities>
    <activity><schedule type="periodic" period="10"/><components><component name="gen"/></components></activity>
  </activities>
</package>
"""


def test_wrong_attribute_value_names_file_line_and_expectation(coco_launch: Path, tmp_path: Path) -> None:
    app = tmp_path / "broken.xml"
    out = tmp_path / "never.csv"
    app.write_text(BROKEN_CONNECTION.format(out=out))
    result = run_launcher(coco_launch, str(app))
    assert result.returncode == 1
    assert f"{app}:4:" in result.stderr
    assert "frequency" in result.stderr and "expected a number" in result.stderr
    assert not out.exists(), "nothing may start when the file is wrong"


def test_unknown_port_lists_valid_ports(coco_launch: Path, tmp_path: Path) -> None:
    app = tmp_path / "broken.xml"
    app.write_text(BROKEN_CONNECTION.format(out=tmp_path / "x.csv").replace('value="fast"', 'value="2"'))
    result = run_launcher(coco_launch, str(app), "--check")
    assert result.returncode == 1
    assert f"{app}:11:" in result.stderr
    assert "no port 'sampel'" in result.stderr and "did you mean 'sample'" in result.stderr


def test_xml_syntax_error_has_line(coco_launch: Path, tmp_path: Path) -> None:
    app = tmp_path / "syntax.xml"
    app.write_text("<package>\n  <components>\n  </component>\n</package>\n")
    result = run_launcher(coco_launch, str(app))
    assert result.returncode == 1
    assert f"{app}:3:" in result.stderr


@pytest.mark.parametrize("sample", ["legacy_config.xml", "config.xml", "config_pipeline.xml"])
def test_original_coco_samples_report_their_tasks_as_unknown(coco_launch: Path, sample: str) -> None:
    path = SHARED_DATA / "coco_xml" / sample
    if not path.exists():
        pytest.skip(f"{path} is absent (the shared test data is not next to this checkout)")
    result = run_launcher(coco_launch, str(path), "--check")
    assert result.returncode == 1
    assert "unknown component" in result.stderr
    # The message lists what is installed, so the user sees what can be used instead.
    assert "SignalGenerator" in result.stderr and "MovingAverage" in result.stderr


def test_list_shows_installed_components(coco_launch: Path) -> None:
    result = run_launcher(coco_launch, "--list")
    assert result.returncode == 0
    assert "MovingAverage  (coco_core.demo.moving_average:MovingAverage)" in result.stdout
    assert "operation set_window" in result.stdout
    assert "attribute window: int = 8" in result.stdout
    # Ports a component makes from its attributes are described too (a ROSInterface's, one per topic).
    found = re.search(r"^ROSInterface  \(.*?(?=^\S)", result.stdout, re.M | re.S)
    rosinterface = found.group(0) if found else ""
    assert "ports one output per subscribe spec" in rosinterface and "JointState -> JointSample" in rosinterface


@pytest.mark.parametrize("words, said", [
    (["mode2=all"], "argument 'mode2=all' must look like name:=value"),
    (["windw:=4"], "arg 'windw' was given (windw:=4) but no file declares it; did you mean 'window'?"),
    (["--allow-unknown"], "--allow-unknown goes with --check only"),
    (["--host", "station"], "--host station: application demo_pipeline declares no <host>"),
])
def test_a_wrong_command_line_exits_with_2(words: list[str], said: str, capsys: pytest.CaptureFixture[str]) -> None:
    """The README's exit statuses: 2 for a wrong command line (it was 1, as for a wrong file)."""
    from coco_core.launcher import main

    assert main([DEMO_APP, *words, "--duration", "0.1"]) == 2
    assert said in capsys.readouterr().err


def test_a_wrong_file_with_a_wrong_command_line_exits_with_1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Both wrong: the file's errors come first (fixing the command line alone would not do)."""
    from coco_core.launcher import main

    app = tmp_path / "broken.xml"
    app.write_text(BROKEN_CONNECTION.format(out=tmp_path / "never.csv").replace('data="DATA"', 'data="FOO"'))
    assert main([str(app), "nothing:=1", "--check"]) == 1
    err = capsys.readouterr().err
    assert "no file declares it" in err and 'data="FOO" is not valid' in err
