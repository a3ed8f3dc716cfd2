"""Fails the test run when a suite ran no test or any test failed.

colcon treats pytest's "no tests collected" (exit code 5) as success, and `colcon test-result` exits 0
on an empty result set; for this project both are failures: a package with test files must run some,
and the whole run must run at least one. Prints the slowest tests (where the run's time goes, so that
a test that grew slow is seen) and the closing line CI reads.
"""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
from pathlib import Path

SLOWEST = 10
"""How many of the slowest tests the run names at its end."""


def count(result_file: Path) -> tuple[int, int, int]:
    """Return (tests, failed, skipped) of one JUnit XML file."""
    root = ET.parse(result_file).getroot()
    suites = [root] if root.tag == "testsuite" else root.findall("testsuite")
    tests = failed = skipped = 0
    for suite in suites:
        tests += int(suite.get("tests", 0))
        failed += int(suite.get("failures", 0)) + int(suite.get("errors", 0))
        skipped += int(suite.get("skipped", 0))
    return tests, failed, skipped


def durations(result_file: Path) -> list[tuple[float, str]]:
    """(seconds, suite::test) of every test of one JUnit XML file: setup, call and teardown together."""
    suite = result_file.parent.name
    return [(float(case.get("time", 0)), f"{suite}: {case.get('classname', '')}::{case.get('name', '')}")
            for case in ET.parse(result_file).getroot().iter("testcase")]


def slowest(files: list[Path], count: int) -> list[str]:
    """The lines that name the ``count`` slowest tests of all suites, slowest first."""
    timed = sorted((timing for result_file in files for timing in durations(result_file)), reverse=True)
    return [f"{seconds:8.1f} s  {name}" for seconds, name in timed[:count]]


def has_tests(suite: str, workspace: Path) -> bool:
    """Whether the package (or the workspace-level ``test/``, whose suites are ``workspace_*``) has test
    files that should have run."""
    folder = workspace / "test" if suite.startswith("workspace_") else workspace / suite / "test"
    return any(folder.glob("test_*.py"))


def main(build_base: str) -> int:
    files = sorted(Path(build_base).glob("*/pytest.xml"))
    workspace = Path(build_base).resolve().parent
    total = failed = skipped = 0
    problems = []
    for result_file in files:
        tests, bad, skip = count(result_file)
        suite = result_file.parent.name
        if tests == 0 and has_tests(suite, workspace):
            problems.append(f"{suite}: has test files but no test ran")
        elif tests == 0:
            print(f"note: {suite} has no tests yet", file=sys.stderr)
        total, failed, skipped = total + tests, failed + bad, skipped + skip
    if not files:
        problems.append(f"no test results under {build_base}/*/pytest.xml")
    if files:
        print(f"the {SLOWEST} slowest tests:")
        print("\n".join(slowest(files, SLOWEST)))
    for problem in problems:
        print(f"error: {problem}", file=sys.stderr)
    print(f"{total - failed - skipped} passed, {failed} failed, {skipped} skipped")
    return 1 if problems or failed or total == 0 else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else "build"))
