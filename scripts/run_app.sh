#!/usr/bin/env bash
# The main job: set up and build the workspace, then run the default application on generated data
# (no hardware needed). Extra arguments go to the launcher, e.g. `--duration 30` or `window:=16`.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck source=setup.sh
source "$ROOT/scripts/setup.sh"
cd "$ROOT"
exec "$ROOT/install/coco_core/lib/coco_core/coco-launch" config/demo_pipeline.xml \
    --duration 6 --profile 3 "$@"
