#!/usr/bin/env bash
# Builds the workspace with colcon (per-package arguments come from colcon.meta).
set -euo pipefail
source "$(dirname "$0")/env.sh"
cd "$WS_ROOT"
JOBS="${ADROIT_BUILD_JOBS:-$(nproc)}"
export MAKEFLAGS="-j$JOBS"
colcon --log-base log build --metas colcon.meta --parallel-workers 1 \
  --event-handlers console_cohesion- summary+ "$@"
