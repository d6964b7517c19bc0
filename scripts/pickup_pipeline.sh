#!/bin/bash
# Learning from demonstrations and generalisation, end to end (thesis ch. 10-11, issue 37):
#   1. the scripted expert records one demonstration bag per rod angle through the teleop path
#   2. a library job trains one local policy per demonstration (10 iterations of learning from
#      experience each, imitating it) through the trainer's rosservice
#   3. neural-network policies are distilled from the library (6x150 full state, partial
#      observation 6x150 and 4x80, without touch; partial 6x150 also with DAgger rounds)
#   4. pickup_eval evaluates every demonstration replay, local policy, nearest neighbour and
#      network over the rod angle and 100 random angles, and prints the RESULT lines
#
#   bash scripts/pickup_pipeline.sh [OUT_DIR]      # default ~/.ros/pickup_pipeline/<date>
#
# Environment: ITERATIONS (10), ROLLOUTS (5 per iteration), NET_ROLLOUTS (50 per local policy),
# EPOCHS (100), DAGGER (2 rounds), WORKERS (0 = one per core), YAWS (the expert's angles).
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
source "$HERE/env.sh"
source_workspace

OUT="${1:-$HOME/.ros/pickup_pipeline/$(date +%Y%m%d-%H%M%S)}"
ITERATIONS="${ITERATIONS:-10}" ROLLOUTS="${ROLLOUTS:-5}" NET_ROLLOUTS="${NET_ROLLOUTS:-50}"
EPOCHS="${EPOCHS:-100}" DAGGER="${DAGGER:-2}" WORKERS="${WORKERS:-0}" YAWS="${YAWS:-}"
mkdir -p "$OUT"
START=$(date +%s)
step() { echo; echo "=== $(( $(date +%s) - START )) s: $*"; }

record_demonstrations() {
  step "1. expert demonstrations -> $OUT/demos"
  rosrun adroit_teleop pickup_expert --out "$OUT/demos" ${YAWS:+--yaws "$YAWS"}
  mkdir -p "$OUT/demos_txt"
  for bag in "$OUT"/demos/*.bag; do
    rosrun adroit_teleop demos export "$bag" --out "$OUT/demos_txt" --commands mean
  done
}

# The trainer (train.launch, in-process workers) under a master of its own; stopped on exit.
TRAIN_LAUNCH_PID=""
stop_trainer() { [ -n "$TRAIN_LAUNCH_PID" ] && kill -INT "$TRAIN_LAUNCH_PID" 2>/dev/null && wait "$TRAIN_LAUNCH_PID" || true; }
trap stop_trainer EXIT

train_library() {
  step "2. library job: one local policy per demonstration, $ITERATIONS iterations x $ROLLOUTS rollouts"
  roslaunch adroit_launch train.launch scene:=pickup backend:=sim_workers workers:="$WORKERS" \
    > "$OUT/train_launch.log" 2>&1 &
  TRAIN_LAUNCH_PID=$!
  for _ in $(seq 120); do rosservice list 2>/dev/null | grep -q /adroit_learning/train && break; sleep 0.5; done
  rosservice call /adroit_learning/train \
    "{task: pickup, demonstrations: '$OUT/demos', iterations: $ITERATIONS, rollouts: $ROLLOUTS, seed: 1, output_dir: '$OUT/library'}"
  local state=running
  while [ "$state" = running ]; do
    sleep 10
    state=$(rosservice call /adroit_learning/status | sed -n 's/^state: "\(.*\)"/\1/p')
    rosservice call /adroit_learning/status | grep -E '^(iteration|message):' | tr '\n' ' '; echo
  done
  [ "$state" = finished ] || { echo "pickup_pipeline: the library job ended $state" >&2; exit 1; }
  stop_trainer
  TRAIN_LAUNCH_PID=""
}

distill() {  # name observation layers units dagger
  step "3. network $1: $2 inputs, $3 x $4, $NET_ROLLOUTS rollouts per local policy, DAgger rounds $5"
  rosrun adroit_learning train_network_policy --library "$OUT/library/library.txt" --task pickup \
    --observation "$2" --layers "$3" --units "$4" --rollouts "$NET_ROLLOUTS" --epochs "$EPOCHS" \
    --dagger "$5" --workers "$WORKERS" --threads 1 --seed 1 --out "$OUT/networks/$1.policy"
}

evaluate() {
  step "4. evaluation -> $OUT/eval"
  local policies=(--policy "nearest_neighbour=$OUT/library/library.txt")
  for local in "$OUT"/library/yaw_*/final.tvlg; do
    policies+=(--policy "local_$(basename "$(dirname "$local")")=$local")
  done
  for net in "$OUT"/networks/*.policy; do policies+=(--policy "nn_$(basename "$net" .policy)=$net"); done
  rosrun adroit_learning pickup_eval --task pickup "${policies[@]}" --replay-demos "$OUT/demos_txt" \
    --cross-validate "$OUT/library/library.txt" --workers "$WORKERS" --out "$OUT/eval" \
    --require nearest_neighbour=95 --require nn_partial_6x150=85
}

record_demonstrations
train_library
mkdir -p "$OUT/networks"
distill full_6x150 full 6 150 0
distill partial_6x150 partial 6 150 0
distill partial_4x80 partial 4 80 0
distill no_touch_6x150 no_touch 6 150 0
distill partial_6x150_dagger partial 6 150 "$DAGGER"
evaluate
step "done in $(( $(date +%s) - START )) s: tables $OUT/eval/summary.md, plots $OUT/eval/*.png, RESULT lines above"
echo "RESULT adroit_learning/pickup_pipeline_minutes $(( ($(date +%s) - START + 59) / 60 )) min target <= 60 $([ $(( $(date +%s) - START )) -le 3600 ] && echo PASS || echo FAIL)"
