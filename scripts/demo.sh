#!/usr/bin/env bash
# The README's demo command: install, build, run the main demo headless.
# Today the demo loads every scene of the description in MuJoCo, steps it with zero command
# for a few simulated seconds and prints one row per scene.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
source "$here/env.sh"
cd "$WS_ROOT"
"$here/install_deps.sh"
"$here/build.sh"
source_workspace
echo
echo "== ADROIT scenes, 3 simulated seconds each, zero tendon tension =="
rosrun adroit_description scene_report --seconds 3
