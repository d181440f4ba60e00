#!/usr/bin/env bash
# Tiles benchmark (issue #18): simulates one session per length on a long route (a world of
# --extent metres, keyframes 2 m apart) and runs HD removal of it whole (`ltmapper hd`) and tile
# by tile (`ltmapper tiles plan` / `run` / `merge`, every tile in one process, one after another),
# both on the true poses (--poses; the session's own odometry drifts tens of metres over such
# routes without loop closures, which smears every revisit into the map).
# Prints per length: peak RSS (/usr/bin/time -v) and wall seconds per keyframe of both, the tiles,
# the largest tile (its core's map points and the keyframes it reads: a tile job's memory follows
# them), the tiles' parts on disk, and whether the merged HD-free map is the whole-session map byte
# for byte.
# With --pair: two sessions per length (the simulator's changes between them) and the LT-removert
# stage (`ltmapper removert`: HD of both, LD of the pair, the keyframe folders) whole and with
# tiles.stage (every HD and LD tile from files, the keyframe folders cut from the merged clouds);
# prints both peaks and s/kf and whether every PCD and CSV of the output is equal.
# With --ltmap: two sessions per length, the whole LT-removert stage once (kept in the work folder),
# then LT-map's commands on it, each its own process: `map integrate` (creates the store: init and
# the query session), `map objects` and `map live`; prints each one's peak RSS and wall seconds,
# the store's points and the objects found.
# usage: bench/bench_tiles.sh [--lengths "250 500 1000 2000"] [--extent M] [--threads N] [--build DIR] [--work DIR]
#        [--pair | --ltmap] [--set KEY=VALUE]...   (removert keys, e.g. --set tiles.edge_m=100)
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BUILD="$ROOT/build"; WORK=""; LENGTHS="250 500 1000 2000"; EXTENT=1000; THREADS=2; SETS=(); PAIR=0; LTMAP=0
while [ $# -gt 0 ]; do
  case "$1" in
    --lengths) LENGTHS="$2"; shift 2 ;;
    --extent) EXTENT="$2"; shift 2 ;;
    --threads) THREADS="$2"; shift 2 ;;
    --build) BUILD="$2"; shift 2 ;;
    --work) WORK="$2"; shift 2 ;;
    --set) SETS+=(--set "$2"); shift 2 ;;
    --pair) PAIR=1; shift ;;
    --ltmap) PAIR=1; LTMAP=1; shift ;;
    *) echo "unknown argument: $1" >&2; exit 2 ;;
  esac
done
WORK="${WORK:-$(mktemp -d /tmp/ltm_bench_tiles.XXXXXX)}"
EXE="$BUILD/apps/ltmapper"
PYTHON=/usr/bin/python3
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), load $(cut -d' ' -f1-3 /proc/loadavg)"
echo "sessions: world ${EXTENT} m, keyframes 2 m apart, 32 x 512 beams; --threads $THREADS ${SETS[*]:-}"
SESSIONS=$((PAIR + 1))

# Peak RSS [MB] and wall seconds of a command, from /usr/bin/time -v (appended to $WORK/last_time).
timed() {
  /usr/bin/time -v -o "$WORK/last_time" "$@" > /dev/null
  local kb wall
  kb=$(awk -F': ' '/Maximum resident set size/ {print $2}' "$WORK/last_time")
  wall=$(awk -F': ' '/Elapsed \(wall clock\)/ {print $2}' "$WORK/last_time" | awk -F: '{ s = 0; for (i = 1; i <= NF; ++i) s = s * 60 + $i; print s }')
  echo "$((kb / 1024)) $wall"
}

# The simulated sessions of length $1 in $2 (sim/ and its config).
simulate() {
  mkdir -p "$2"
  printf "world:\n  extent_m: %s\nroute:\n  sessions: %s\n  keyframes: %s\n  keyframe_spacing_m: 2.0\nlidar:\n  beams: 32\n  columns: 512\n" \
    "$EXTENT" "$SESSIONS" "$1" > "$2/sim.yaml"
  [ -d "$2/sim/sessions/session_0$PAIR" ] || "$EXE" sim --config "$2/sim.yaml" --out "$2/sim" --quiet --threads "$THREADS"
}

# The arguments of `ltmapper removert` for the pair simulated in $1 on its true poses, out to $2,
# with the bench's keys and any further arguments: into RV (an array; `timed` needs a command).
removert_pair() {
  local dir="$1" out="$2"
  shift 2
  RV=(removert --sessions "$dir/sim/sessions/session_00" "$dir/sim/sessions/session_01"
      --poses "$dir/sim/truth/session_00/poses_world.txt" "$dir/sim/truth/session_01/poses_world.txt"
      "${SETS[@]}" --set out.write_ply=false "$@" --out "$out" --threads "$THREADS" --quiet)
}

if [ "$LTMAP" = 1 ]; then
  printf "| keyframes per session | map points | objects | map integrate peak MB (s) | map objects peak MB (s) | map live peak MB (s) |\n"
  printf "|---|---|---|---|---|---|\n"
  for K in $LENGTHS; do
    dir="$WORK/pair$K"
    simulate "$K" "$dir"
    for s in session_00 session_01; do  # LT-map reads the world poses from LT-SLAM's folder
      mkdir -p "$dir/aligned/$s" && cp "$dir/sim/truth/$s/poses_world.txt" "$dir/aligned/$s/"
    done
    removert_pair "$dir" "$dir/changes"
    [ -f "$dir/changes/pair_00_01/keyframes.csv" ] || "$EXE" "${RV[@]}" > /dev/null
    rm -rf "$dir/ltmap" && mkdir -p "$dir/ltmap"
    store="$dir/ltmap/map.ltmap"
    read -r int_mb int_s < <(timed "$EXE" map integrate --store "$store" --aligned "$dir/aligned" --changes "$dir/changes" --central session_00 --threads "$THREADS" --quiet)
    read -r obj_mb obj_s < <(timed "$EXE" map objects --store "$store" --out "$dir/ltmap/objects" --session "$dir/sim/sessions/session_00" --threads "$THREADS" --quiet)
    read -r live_mb live_s < <(timed "$EXE" map live --store "$store" --out "$dir/ltmap/live.pcd" --threads "$THREADS" --quiet)
    points=$(head -c 4096 "$dir/ltmap/live.pcd" | awk '/^POINTS/ {print $2 + 0; exit}')
    objects=$(($(wc -l < "$dir/ltmap/objects/objects.csv") - 1))
    printf "| %s | %s | %s | %s (%s) | %s (%s) | %s (%s) |\n" "$K" "$points" "$objects" "$int_mb" "$int_s" "$obj_mb" "$obj_s" "$live_mb" "$live_s"
  done
  exit 0
fi

if [ "$PAIR" = 1 ]; then
  printf "| keyframes per session | whole stage peak MB | whole s/kf | tiled stage peak MB | tiled s/kf | files | tiled == whole |\n"
  printf "|---|---|---|---|---|---|---|\n"
  for K in $LENGTHS; do
    dir="$WORK/pair$K"
    simulate "$K" "$dir"
    removert_pair "$dir" "$dir/whole"
    read -r whole_mb whole_s < <(timed "$EXE" "${RV[@]}")
    removert_pair "$dir" "$dir/tiled" --set tiles.stage=true
    read -r tiled_mb tiled_s < <(timed "$EXE" "${RV[@]}")
    files=0; differ=0
    while IFS= read -r f; do
      files=$((files + 1))
      cmp -s "$dir/whole/$f" "$dir/tiled/$f" || differ=$((differ + 1))
    done < <(cd "$dir/whole" && find . -name '*.pcd' -o -name '*.csv')
    equal=$([ "$differ" = 0 ] && echo "bytes equal" || echo "$differ DIFFERENT")
    printf "| %s | %s | %.4f | %s | %.4f | %s | %s |\n" "$K" "$whole_mb" "$(awk "BEGIN { print $whole_s / (2 * $K) }")" \
      "$tiled_mb" "$(awk "BEGIN { print $tiled_s / (2 * $K) }")" "$files" "$equal"
  done
  exit 0
fi

printf "| keyframes | map points (removed %%) | tiles (edge m) | largest tile: points, keyframes | parts MB | whole peak MB | whole s/kf | tiled peak MB | tiled s/kf | tiled == whole |\n"
printf "|---|---|---|---|---|---|---|---|---|---|\n"
for K in $LENGTHS; do
  dir="$WORK/k$K"
  simulate "$K" "$dir"
  ses="$dir/sim/sessions/session_00"
  poses="$dir/sim/truth/session_00/poses_world.txt"
  read -r whole_mb whole_s < <(timed "$EXE" hd "$ses" --poses "$poses" "${SETS[@]}" --out "$dir/whole.pcd" --threads "$THREADS" --quiet)
  read -r plan_mb plan_s < <(timed "$EXE" tiles plan "$ses" --poses "$poses" "${SETS[@]}" --out "$dir/plan" --threads "$THREADS" --quiet)
  read -r run_mb run_s < <(timed "$EXE" tiles run "$dir/plan" --threads "$THREADS" --quiet)
  read -r merge_mb merge_s < <(timed "$EXE" tiles merge "$dir/plan" --out "$dir/merged" --quiet)
  tiled_mb=$(printf "%s\n%s\n%s\n" "$plan_mb" "$run_mb" "$merge_mb" | sort -n | tail -1)
  tiled_s=$(awk "BEGIN { print $plan_s + $run_s + $merge_s }")
  points=$(awk -F': ' '/"map_points"/ {gsub(/,/, "", $2); print $2}' "$dir/merged/report.json")
  removed=$("$PYTHON" -c "import json, sys; r = json.load(open(sys.argv[1])); print(round(100 * (r['removed'] + r['dilated']) / r['map_points'], 2))" "$dir/merged/report.json")
  tiles=$(awk -F': ' '/"tiles"/ {gsub(/,/, "", $2); print $2; exit}' "$dir/merged/report.json")
  edge=$("$PYTHON" -c "import json, sys; p = json.load(open(sys.argv[1])); print(round(p['edge_voxels'] * p['voxel_m'], 1))" "$dir/plan/plan.json")
  largest=$(cat "$dir"/plan/parts/tile_*/tile.json | awk -F': ' '/"map_points"/ {v = $2 + 0; if (v > m) m = v} END {print m}')
  most_kf=$("$PYTHON" -c "import json, sys; print(max(sum(e - b + 1 for b, e in t['keyframe_runs']) for t in json.load(open(sys.argv[1]))['tiles']))" "$dir/plan/plan.json")
  parts_mb=$(du -sm "$dir/plan/parts" | cut -f1)
  equal=$(cmp -s "$dir/whole.pcd" "$dir/merged/static_map.pcd" && echo "bytes equal" || echo "DIFFERENT")
  printf "| %s | %s (%s) | %s (%s) | %s, %s | %s | %s | %.4f | %s (plan %s, run %s, merge %s) | %.4f | %s |\n" "$K" "$points" "$removed" "$tiles" \
    "$edge" "$largest" "$most_kf" "$parts_mb" "$whole_mb" \
    "$(awk "BEGIN { print $whole_s / $K }")" "$tiled_mb" "$plan_mb" "$run_mb" "$merge_mb" "$(awk "BEGIN { print $tiled_s / $K }")" "$equal"
done
