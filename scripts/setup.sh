#!/usr/bin/env bash
# Prepares the workspace from a fresh clone and leaves it sourced: system packages (when missing),
# the virtual environment with the pinned requirements, and a colcon build.
# Sourced by run_app.sh and run_tests.sh, or by a user (`source scripts/setup.sh`); safe to run again
# (each step is skipped when up to date). The steps run in a subshell with `set -euo pipefail`, so a
# failure ends the setup, never the caller's shell, and the caller's shell options are left as they were.

COCO_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$COCO_ROOT/.venv"

log() { printf '[setup] %s\n' "$*" >&2; }

pick_python() {
    local candidate
    for candidate in python3.13 python3.12 python3.11 python3; do
        if command -v "$candidate" >/dev/null 2>&1 &&
            "$candidate" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
            echo "$candidate"
            return
        fi
    done
    echo "CoCo needs Python 3.11 or newer; none was found on PATH" >&2
    exit 1
}

apt_install() {
    # Debian/Ubuntu: install what is missing; we run as root on these machines, sudo elsewhere.
    local sudo=""
    [ "$(id -u)" -eq 0 ] || sudo="sudo"
    log "installing system packages: $*"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "$@" >/dev/null
}

ensure_venv() {
    local python
    python="$(pick_python)"
    if [ ! -x "$VENV/bin/python" ]; then
        if ! "$python" -c 'import ensurepip, venv' 2>/dev/null; then
            apt_install "python3-venv"
        fi
        log "creating $VENV with $python"
        "$python" -m venv "$VENV"
    fi
    # The ROS wheels install package.xml files under the venv: keep colcon from crawling them.
    touch "$VENV/COLCON_IGNORE"
}

ensure_requirements() {
    local stamp="$VENV/.requirements.sha256" want
    want="$(sha256sum "$COCO_ROOT/requirements.txt" | cut -d' ' -f1)"
    if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
        log "installing pinned requirements (first run takes a few minutes)"
        "$VENV/bin/python" -m pip install --quiet --upgrade pip
        "$VENV/bin/python" -m pip install --quiet -r "$COCO_ROOT/requirements.txt"
        echo "$want" > "$stamp"
    fi
}

ensure_wheel_build_paths() {
    # vendor/tf2_msgs is generated with the rosidl wheels' CMake code, whose exported Python
    # targets name the wheel builder's interpreter (/opt/python/cpXY-cpXY/include/pythonX.Y and
    # its numpy include dir) instead of ours. Rewrite those paths inside this venv's own export
    # files to this interpreter's headers and this venv's numpy headers: nothing outside the
    # workspace is written and no root is needed. pip restores the originals when it reinstalls a
    # wheel, so this runs after every requirements step (a file already rewritten is left alone).
    local python_include numpy_include files=()
    [ -d "$VENV/share" ] || return 0
    mapfile -d '' files < <(grep -rlZ --include='*.cmake' '/opt/python/' "$VENV/share" 2>/dev/null || true)
    [ "${#files[@]}" -gt 0 ] || return 0
    python_include="$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')"
    numpy_include="$("$VENV/bin/python" -c 'import numpy; print(numpy.get_include())')"
    log "pointing ${#files[@]} CMake export files of the wheels at $python_include and $numpy_include"
    sed -i -E \
        -e "s#/opt/python/[^/\";]+/lib/python3\.[0-9]+/site-packages/numpy/(_core|core)/include#${numpy_include}#g" \
        -e "s#/opt/python/[^/\";]+/include/python3\.[0-9]+#${python_include}#g" \
        "${files[@]}"
}

build_inputs() {
    # What a build reads from the workspace: the name, time and size of every file of the packages
    # (tracked or new, not ignored: no __pycache__ or numba cache; tests are not built), config/ (coco_ros
    # installs it to share/coco_ros/config), colcon.meta and the requirements. Prints nothing outside a git checkout: then every run builds.
    (cd "$COCO_ROOT" && git rev-parse --is-inside-work-tree >/dev/null 2>&1 || exit 0
     {
         git ls-files -z --cached --others --exclude-standard -- colcon.meta config coco_core coco_ros \
             coco_mr_vision coco_mr_haptics coco_mr_display interfaces vendor ':(exclude)*/test/*' | xargs -0 -r stat -c '%n %Y %s' 2>/dev/null || true
         cat "$VENV/.requirements.sha256" 2>/dev/null
     } | sha256sum | cut -d' ' -f1)
}

build_workspace() {
    # colcon build takes ~20 s even when nothing changed; the documented commands and run_app.sh set
    # up again and again, so the build is skipped when its inputs are those of the last good build.
    local stamp="$COCO_ROOT/build/.coco-build-inputs" inputs
    inputs="$(build_inputs)"
    if [ -n "$inputs" ] && [ -f "$COCO_ROOT/install/setup.bash" ] && [ "$(cat "$stamp" 2>/dev/null)" = "$inputs" ]; then
        log "workspace up to date (no package file changed since the last build)"
        return
    fi
    log "colcon build"
    # The interface packages (vendor/tf2_msgs, interfaces/coco_interfaces) find ament_cmake and the rosidl generators in the
    # venv's prefix, where the wheels install them (set for the build only).
    (cd "$COCO_ROOT" &&
        AMENT_PREFIX_PATH="$VENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}" \
        CMAKE_PREFIX_PATH="$VENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}" \
        colcon --log-base log build --build-base build --install-base install \
        --event-handlers console_direct- console_stderr- summary+ >&2)
    if [ -n "$inputs" ]; then
        echo "$inputs" > "$stamp"
    fi
}

ensure_system_packages() {
    # Chromium checks the transformation graph's web page; graphviz renders its DOT export.
    local missing=()
    command -v chromium >/dev/null 2>&1 || missing+=(chromium)
    command -v dot >/dev/null 2>&1 || missing+=(graphviz)
    # vendor/tf2_msgs is an ament_cmake package: its rosidl code is generated and compiled.
    command -v cmake >/dev/null 2>&1 || missing+=(cmake)
    command -v g++ >/dev/null 2>&1 || missing+=(g++)
    # coco_mr_display renders with OpenGL 3.3 through Mesa (llvmpipe when there is no GPU): EGL for
    # headless output, GLX for GLFW windows; the window tests run under Xvfb.
    ldconfig -p | grep -q 'libEGL_mesa.so' || missing+=(libegl1 libegl-mesa0)
    ldconfig -p | grep -q 'libGLX_mesa.so' || missing+=(libgl1 libglx-mesa0)
    [ -d /usr/lib/x86_64-linux-gnu/dri ] || [ -d /usr/lib/aarch64-linux-gnu/dri ] || missing+=(libgl1-mesa-dri)
    command -v Xvfb >/dev/null 2>&1 || missing+=(xvfb)
    if [ "${#missing[@]}" -gt 0 ]; then
        apt_install "${missing[@]}"
    fi
}

prepare_workspace() {
    set -euo pipefail
    ensure_system_packages
    ensure_venv
    ensure_requirements
    # shellcheck disable=SC1091
    source "$VENV/bin/activate"
    ensure_wheel_build_paths
    build_workspace
}

# Not `if ! (prepare_workspace)`: bash ignores `set -e` inside a condition, so a failing step would not
# stop the ones after it. Under the caller's own `set -e` (run_tests.sh) a failure stops the caller here.
(prepare_workspace)
_coco_setup_status=$?
if [ "$_coco_setup_status" -ne 0 ]; then
    log "setup failed (see above)"
    return "$_coco_setup_status" 2>/dev/null || exit "$_coco_setup_status"
fi
unset _coco_setup_status
# The activation scripts read unset variables: `set -u` is lifted around them, then restored.
case $- in *u*) _coco_nounset=1 ;; *) _coco_nounset= ;; esac
set +u
# shellcheck disable=SC1091
source "$VENV/bin/activate"
# shellcheck disable=SC1091
source "$COCO_ROOT/install/setup.bash"
[ -z "$_coco_nounset" ] || set -u
unset _coco_nounset
