#!/usr/bin/env bash
# The main job: set up and build the workspace, then run the default application, the Baxter
# teleoperation replay (config/baxter_teleop_replay.xml), on a generated session (no hardware needed).
# The session bag is generated once, on first use, into out/baxter_session. Extra arguments go to the
# launcher, e.g. `rate:=2`, `near:=0.05`, `display:=false` (no rendering) or `--duration 5`.
#
# `./scripts/run_app.sh palpation [args]` runs the remote palpation application instead
# (config/palpation_replay.xml) on its generated session (out/palpation_session, made on first use by
# palpation-session); its outputs go to out/palpation.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck source=setup.sh
source "$ROOT/scripts/setup.sh"
cd "$ROOT"

APP="teleop"
if [ "${1:-}" = "palpation" ]; then
    APP="palpation"
    shift
fi
if [ "$APP" = "palpation" ]; then
    SESSION="out/palpation_session"
    OUTPUT="out/palpation"
    GENERATOR="palpation-session"
    XML="config/palpation_replay.xml"
    WHAT="remote palpation"
else
    SESSION="out/baxter_session"
    OUTPUT="out/teleop"
    GENERATOR="baxter-session"
    XML="config/baxter_teleop_replay.xml"
    WHAT="teleoperation"
fi
for arg in "$@"; do  # the launcher takes the last value of an argument: so do we
    case "$arg" in
        bag:=*) SESSION="${arg#bag:=}" ;;
        output:=*) OUTPUT="${arg#output:=}" ;;
    esac
done

# A session folder only ever appears complete: it is generated beside it and moved in place at the
# end, so an interrupted generation is simply started again.
if [ ! -f "$SESSION/metadata.yaml" ]; then
    if [ -e "$SESSION" ]; then
        echo "$SESSION exists but holds no complete bag (no metadata.yaml): move it away or pass bag:=<folder>" >&2
        exit 1
    fi
    partial="$(dirname "$SESSION")/.partial-$(basename "$SESSION")"
    rm -rf "$partial"
    mkdir -p "$partial"
    echo "Generating the $WHAT session $SESSION (first run only)"
    "$ROOT/install/coco_ros/lib/coco_ros/$GENERATOR" "$partial/$(basename "$SESSION")"
    mv "$partial/$(basename "$SESSION")" "$SESSION"
    rmdir "$partial"
fi

started="$(mktemp)"  # what this run rendered is newer than this file (the folder may hold older runs')
trap 'rm -f "$started"' EXIT
# Damaged input (exit status 1) still leaves a run whose summary says what was damaged: print it,
# then exit with the launcher's status.
status=0
"$ROOT/install/coco_core/lib/coco_core/coco-launch" "$XML" \
    bag:="$SESSION" output:="$OUTPUT" --profile 6 "$@" || status=$?

if [ "$OUTPUT/summary.json" -nt "$started" ]; then
    echo
    if [ "$APP" = "palpation" ]; then
        echo "Palpation summary ($OUTPUT/summary.json; forces: $OUTPUT/haptic.csv):"
        python -m coco_ros.palpation "$OUTPUT/summary.json"
    else
        echo "Teleoperation summary ($OUTPUT/summary.json):"
        python -m coco_ros.teleop "$OUTPUT/summary.json"
    fi
fi

# The rendered view (not with display:=false): a video or PNG sequence, and a contact sheet.
if [ "$OUTPUT/contact_sheet.png" -nt "$started" ]; then
    echo
    if [ "$OUTPUT/frames.mp4" -nt "$started" ]; then
        echo "Rendered view:  $OUTPUT/frames.mp4"
    else
        frames=("$OUTPUT"/frames_*.png)
        echo "Rendered view:  $OUTPUT/frames_*.png (${#frames[@]} frames)"
    fi
    echo "Contact sheet:  $OUTPUT/contact_sheet.png"
fi
exit "$status"
