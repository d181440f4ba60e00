#!/usr/bin/env bash
# Lifelong add benchmark (issue #16): simulates S sessions of K keyframes of one site, builds the
# map of the first two with `ltmapper run`, then adds the others one at a time with
# `ltmapper add` and prints, per add: time per step, store bytes and their growth. The cost of an
# add must not grow with the number of sessions already in the map (flat within 20 % from the
# 2nd add on). Optionally (--batch) runs the batch `ltmapper run` of all S sessions and compares
# its live map with the incremental one (eval restore: Chamfer table and the share of each map's
# points with a point of the same class within one map voxel in the other, both ways: the
# equivalence tests/test_pipeline.cpp asserts for one add, AddingASessionEqualsTheBatchRun).
# usage: bench/bench_add.sh [--sessions S] [--keyframes K] [--build DIR] [--work DIR] [--batch]
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BUILD="$ROOT/build"; WORK=""; S=8; K=150; BATCH=0
while [ $# -gt 0 ]; do
  case "$1" in
    --sessions) S="$2"; shift 2 ;;
    --keyframes) K="$2"; shift 2 ;;
    --build) BUILD="$2"; shift 2 ;;
    --work) WORK="$2"; shift 2 ;;
    --batch) BATCH=1; shift ;;
    *) echo "unknown argument: $1" >&2; exit 2 ;;
  esac
done
WORK="${WORK:-$(mktemp -d /tmp/ltm_bench_add.XXXXXX)}"
EXE="$BUILD/apps/ltmapper"
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), load $(cut -d' ' -f1-3 /proc/loadavg)"
mkdir -p "$WORK"
sed -e "s/^\(  sessions:\) *[0-9]*/\1 $S/" -e "s/^\(  keyframes:\) *[0-9]*/\1 $K/" \
    "$ROOT/config/params_sim.yaml" > "$WORK/params_sim.yaml"
[ -d "$WORK/sim/sessions/session_0$((S - 1))" ] || "$EXE" sim --config "$WORK/params_sim.yaml" --out "$WORK/sim" --quiet
SES="$WORK/sim/sessions"
rm -rf "$WORK/inc"
/usr/bin/time -f "%e" -o "$WORK/t_run" "$EXE" run --quiet --sessions "$SES/session_00" "$SES/session_01" --out "$WORK/inc" > /dev/null
echo "run session_00 session_01: $(cat "$WORK/t_run") s, store $(stat -c %s "$WORK/inc/map.ltmap") bytes"
# CPU seconds (user + system) next to wall time: on a shared machine the wall time measures the
# neighbours too.
printf "| add | session | wall s | CPU s | LT-SLAM s | LT-removert s | LT-map s | store bytes | growth |\n|---|---|---|---|---|---|---|---|---|\n"
for i in $(seq 2 $((S - 1))); do
  name=$(printf "session_%02d" "$i")
  before=$(stat -c %s "$WORK/inc/map.ltmap")
  if ! /usr/bin/time -f "%e %U %S" -o "$WORK/t_add" "$EXE" add --quiet --map "$WORK/inc" "$SES/$name" \
       > "$WORK/add_$name.md" 2> "$WORK/add_$name.err"; then
    echo "| $((i - 1)) | $name | $(tail -1 "$WORK/t_add" | cut -d' ' -f1) | | NOT aligned (no session of the map overlaps it; nothing changed) | | | $before | 0 |"
    continue
  fi
  after=$(stat -c %s "$WORK/inc/map.ltmap")
  steps=$(grep -E "^\| LT-" "$WORK/add_$name.md" | awk -F'|' '{gsub(/ /,"",$3); printf "%s | ", $3}')
  read -r wall user sys < "$WORK/t_add"
  echo "| $((i - 1)) | $name | $wall | $(awk "BEGIN { print $user + $sys }") | ${steps}$after | $((after - before)) |"
done
if [ "$BATCH" = 1 ]; then
  all=(); for i in $(seq 0 $((S - 1))); do all+=("$SES/$(printf "session_%02d" "$i")"); done
  /usr/bin/time -f "%e" -o "$WORK/t_batch" "$EXE" run --quiet --sessions "${all[@]}" --out "$WORK/batch" > /dev/null
  echo "batch run of $S sessions: $(cat "$WORK/t_batch") s, store $(stat -c %s "$WORK/batch/map.ltmap") bytes"
  echo "incremental vs batch live map (Chamfer over patches and same class, eval restore):"
  for m in inc batch; do  # the store's live map with its classes (PLY keeps the class field)
    "$EXE" map export --quiet --store "$WORK/$m/map.ltmap" --out "$WORK/$m/live_labelled.ply" > /dev/null
  done
  "$EXE" eval restore --quiet --map-a "$WORK/inc/live_labelled.ply" --map-b "$WORK/batch/live_labelled.ply" |
    grep -E "^\||^Same class" || true
fi
