"""Fails the test run when a suite ran no test or any test failed.

colcon treats pytest's "no tests collected" (exit code 5) as success, and `colcon test-result` exits 0
on an empty result set; for this project both are failures. Prints the closing line CI reads.
"""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
from pathlib import Path


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


def main(build_base: str) -> int:
    files = sorted(Path(build_base).glob("*/pytest.xml"))
    total = failed = skipped = 0
    problems = []
    for result_file in files:
        tests, bad, skip = count(result_file)
        suite = result_file.parent.name
        if tests == 0:
            problems.append(f"{suite}: no test ran")
        total, failed, skipped = total + tests, failed + bad, skipped + skip
    if not files:
        problems.append(f"no test results under {build_base}/*/pytest.xml")
    for problem in problems:
        print(f"error: {problem}", file=sys.stderr)
    print(f"{total - failed - skipped} passed, {failed} failed, {skipped} skipped")
    return 1 if problems or failed or total == 0 else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else "build"))
