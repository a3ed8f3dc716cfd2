#!/usr/bin/env bash
# The whole test suite: set up and build the workspace, then, side by side, the packages' tests with
# colcon (three: coco_core, coco_ros, the others), the workspace-level tests in test/ and the type
# check of the packages with mypy; print each one's output whole as it ends, then `colcon
# test-result --verbose` and the slowest tests, and fail when any test failed, when no test ran or
# when mypy reports an error.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck source=setup.sh
source "$ROOT/scripts/setup.sh"
cd "$ROOT"

export PYTEST_ADDOPTS="--timeout=300 ${PYTEST_ADDOPTS:-}"
# Fast DDS segments that ROS processes killed by an earlier run left in /dev/shm: an abandoned port
# makes every later participant on it hang while it is created (coco_ros/fastdds_segments.py).
python -m coco_ros.fastdds_segments
LOGS="build/test_logs"
# build/test_inputs: sessions the test processes generate once per run and share (test/conftest.py).
rm -rf build/*/pytest.xml build/workspace_tests build/workspace_apps build/workspace_documented build/workspace_alone \
    build/test_inputs "$LOGS"
mkdir -p build/workspace_tests build/workspace_apps build/workspace_documented build/workspace_alone "$LOGS"
# The parts of the robots' mesh files, made by the first process of the run that draws them and read
# by the others (COCO_MESH_CACHE, docs/display.md): Baxter's take ~2.5 s of CPU to read and simplify,
# and a dozen launches draw it.
export COCO_MESH_CACHE="$ROOT/build/test_inputs/meshes"

# The suites are independent (each reads the built workspace, none writes it) and mostly wait: on
# applications that run for seconds, on DDS discovery, on child processes. Run one after the other
# they left one of the two cores idle most of the time; side by side the run takes about as long as
# the longest of them. Each one's output goes to its own log, printed whole when it ends.
declare -A SUITE_OF=() LABEL_OF=()
start_suite() {  # start_suite NAME LABEL COMMAND...: its output in $LOGS/NAME.log
    local name="$1" label="$2"
    shift 2
    # Its log ends with the CPU time it used (`times`: the processes it waited for, theirs included):
    # the run is CPU-bound on a 2-core machine, so that, not each suite's length, says where it goes.
    ( code=0; "$@" || code=$?; echo "CPU time of this suite (user, system; the second line: its processes)"; times; exit $code ) \
        >"$LOGS/$name.log" 2>&1 &
    SUITE_OF[$!]="$name"
    LABEL_OF[$name]="$label"
    echo "started: $label"
}
# A test that hangs where pytest's --timeout cannot reach it (blocked in C code with the Python lock
# held) must fail the run, not outlast the CI's limit: the package tests get 40 minutes (about 5 on a
# 2-core machine), then timeout ends colcon and every process it started. colcon runs a package's
# tests after those of the packages it depends on, which nothing here needs (they only read what the
# build installed): coco_core and coco_ros, the largest, run beside the others, each colcon with its
# own log base. In one colcon, coco_ros (~190 s) waited for coco_mr_vision, then coco_mr_display and
# coco_mr_haptics (~140 s): that chain, ~330 s, was the longest of the suites.
package_tests() {  # package_tests LOG_BASE COLCON_SELECTION...
    local log_base="$1"
    shift
    timeout --kill-after=30 2400 colcon --log-base "$log_base" test --build-base build --install-base install \
        --event-handlers console_direct+ summary+ "$@"
}
SECONDS=0
# The type checker (mypy.ini): the five packages must stay clean, and every `type: ignore` needed.
start_suite mypy "type check (mypy)" python -m mypy
# The numba kernels compiled once into the installed packages' cache, beside mypy, before the suites
# that use them start: on a fresh build each of their processes compiled them at the same time
# (scripts/compile_kernels.py says why). A failure here shows again in the tests that use them.
python scripts/compile_kernels.py >"$LOGS/compile_kernels.log" 2>&1 || true
tail -n 1 "$LOGS/compile_kernels.log"
start_suite core "coco_core's tests (colcon test)" package_tests log/test_core --packages-select coco_core
start_suite ros "coco_ros's tests (colcon test)" package_tests log/test_ros --packages-select coco_ros
start_suite packages "the other packages' tests (colcon test)" package_tests log/test_packages \
    --packages-skip coco_core coco_ros
# The workspace tests in three pytest processes: the Baxter and camera apps (they replay and render for
# seconds each) with the signal tests (launchers stopped at chosen moments: ~40 s, moved here from the
# rest, which was the longer of the two), the documented commands (the README's and docs' command
# lines, run side by side in the test: about a minute, mostly waiting on applications) and the rest; a
# new test file goes to the rest. The remote palpation app (six processes that need both cores) runs
# alone once these are done: ALONE.
APPS=(test/test_baxter_*.py test/test_camera_registration_app.py test/test_signals.py)
DOCUMENTED=(test/test_documented_commands.py)
ALONE=(test/test_palpation_app.py test/test_palpation_bad_input.py)
start_suite apps "workspace tests: the apps (test/)" \
    python -m pytest "${APPS[@]}" -o cache_dir=build/workspace_apps/.pytest_cache \
    --junit-xml=build/workspace_apps/pytest.xml --junit-prefix=workspace
start_suite documented "workspace tests: the documented commands (test/)" \
    python -m pytest "${DOCUMENTED[@]}" -o cache_dir=build/workspace_documented/.pytest_cache \
    --junit-xml=build/workspace_documented/pytest.xml --junit-prefix=workspace
start_suite workspace "workspace tests: the rest (test/)" \
    python -m pytest test "${APPS[@]/#/--ignore=}" "${DOCUMENTED[@]/#/--ignore=}" "${ALONE[@]/#/--ignore=}" \
    -o cache_dir=build/workspace_tests/.pytest_cache --junit-xml=build/workspace_tests/pytest.xml --junit-prefix=workspace

status=0
while [ "${#SUITE_OF[@]}" -gt 0 ]; do
    finished=""
    suite_status=0
    wait -n -p finished "${!SUITE_OF[@]}" || suite_status=$?
    name="${SUITE_OF[$finished]}"
    unset "SUITE_OF[$finished]"
    echo
    echo "===== ${LABEL_OF[$name]}: exit status $suite_status, ${SECONDS} s after the start ====="
    cat "$LOGS/$name.log"
    [ "$suite_status" -eq 0 ] || status=$suite_status
done
echo
echo "===== workspace tests: alone (test/), ${SECONDS} s after the start ====="
( code=0; python -m pytest "${ALONE[@]}" -o cache_dir=build/workspace_alone/.pytest_cache \
    --junit-xml=build/workspace_alone/pytest.xml --junit-prefix=workspace || code=$?
    echo "CPU time of this suite (user, system; the second line: its processes)"; times; exit $code ) || status=$?
colcon test-result --test-result-base build --verbose || status=$?
python scripts/check_test_results.py build || status=$?
echo "${SECONDS} s in all; CPU time of the whole run (user, system; the second line: its processes):"
times
exit "$status"
