#!/usr/bin/env bash
# The whole pipeline on the built-in example: simulate the default scenario, run LT-SLAM ->
# LT-removert -> LT-map, score every stage against the simulator's truth, render pictures and
# write OUT/report.html + OUT/report.md. Every step is a plain `ltmapper` command, so this file
# doubles as a worked example of the command line.
#   usage: scripts/demo.sh [OUT_DIR=out/demo] [BUILD_DIR=build]
set -euo pipefail
OUT="${1:-out/demo}"
BUILD="${2:-build}"
LTM="$BUILD/apps/ltmapper"
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
cd "$ROOT"
[ -x "$LTM" ] || { echo "demo: $LTM not found; run 'make build' first" >&2; exit 1; }
# This script's own outputs go first: a run that stops half way leaves no report, figures or
# pictures of an earlier run behind to be read as its own (the simulation is reused by its stamp).
rm -rf "$OUT/eval" "$OUT/renders" "$OUT/snapshots" "$OUT/report.md" "$OUT/report.html"
mkdir -p "$OUT/eval" "$OUT/renders"
step() { printf '\n== %s\n' "$*"; }
T0=$(date +%s)

step "1/6 simulate the default scenario (config/params_sim.yaml)"
# Reused only when made from the same config by the same code (its id is in --version).
STAMP="$("$LTM" --version) $(sha256sum < config/params_sim.yaml)"
if [ ! -f "$OUT/sim/truth/objects.csv" ] || [ "$(cat "$OUT/sim_stamp.txt" 2>/dev/null)" != "$STAMP" ]; then
  rm -rf "$OUT/sim" "$OUT/sim_stamp.txt"
  "$LTM" sim --config config/params_sim.yaml --out "$OUT/sim"
  echo "$STAMP" > "$OUT/sim_stamp.txt"
else
  echo "simulation found in $OUT/sim (same config, same code), reused"
fi
SESSIONS=("$OUT"/sim/sessions/session_*)
NAMES=(); for s in "${SESSIONS[@]}"; do NAMES+=("$(basename "$s")"); done

step "2/6 run LT-SLAM -> LT-removert -> LT-map"
"$LTM" run --sessions "${SESSIONS[@]}" --out "$OUT/run" \
  --slam-config config/params_ltslam.yaml --removert-config config/params_ltremovert.yaml \
  --map-config config/params_ltmap.yaml
RUN="$OUT/run"

step "3/6 trajectories against truth (drifted input vs LT-SLAM)"
"$LTM" eval traj --sim "$OUT/sim" --drifted --md "$OUT/eval/10_traj_input.md" --json "$OUT/eval/10_traj_input.json" >/dev/null
"$LTM" eval traj --sim "$OUT/sim" --aligned "$RUN/aligned" --md "$OUT/eval/11_traj_ltslam.md" --json "$OUT/eval/11_traj_ltslam.json" >/dev/null

step "4/6 HD removal and LD changes against point-wise truth"
for s in "${NAMES[@]}"; do
  [ -f "$RUN/changes/$s/static_map.pcd" ] || { echo "skip $s (not aligned)"; continue; }
  "$LTM" eval hd --sim "$OUT/sim" --changes "$RUN/changes" --session "$s" --aligned "$RUN/aligned" \
    --md "$OUT/eval/20_hd_$s.md" --json "$OUT/eval/20_hd_$s.json" >/dev/null
done
for s in "${NAMES[@]:1}"; do
  pair="00_${s#session_}"
  [ -d "$RUN/changes/pair_${NAMES[0]}_$s" ] || [ -d "$RUN/changes/pair_$pair" ] || { echo "skip pair $pair"; continue; }
  # Truth rebuilt from the labelled scans placed with LT-SLAM's poses: the maps' own blur far
  # from the trajectory is no error of the change detection.
  "$LTM" eval ld --sim "$OUT/sim" --changes "$RUN/changes" --pair "$pair" --aligned "$RUN/aligned" --truth-from-scans \
    --md "$OUT/eval/30_ld_$pair.md" --json "$OUT/eval/30_ld_$pair.json" >/dev/null
done

step "5/6 LT-map: rollback to the first session, storage"
"$LTM" map restore --store "$RUN/map.ltmap" --session "${NAMES[0]}" --out "$RUN/restored_${NAMES[0]}.pcd"
"$LTM" eval restore --map-a "$RUN/restored_${NAMES[0]}.pcd" --map-b "$RUN/changes/${NAMES[0]}/static_map.pcd" \
  --md "$OUT/eval/40_restore_positive.md" --json "$OUT/eval/40_restore_positive.json" >/dev/null
"$LTM" eval restore --map-a "$RUN/live.pcd" --map-b "$RUN/changes/${NAMES[0]}/static_map.pcd" \
  --md "$OUT/eval/41_restore_negative.md" --json "$OUT/eval/41_restore_negative.json" >/dev/null
# Live map has the cars parked since session 0, the meta map not; removed cars in neither (then
# the same for every LD object class).
"$LTM" eval livemeta --sim "$OUT/sim" --aligned "$RUN/aligned" --live "$RUN/live.pcd" --meta "$RUN/meta.pcd" \
  --md "$OUT/eval/42_livemeta.md" --json "$OUT/eval/42_livemeta.json" >/dev/null
"$LTM" eval livemeta --sim "$OUT/sim" --aligned "$RUN/aligned" --live "$RUN/live.pcd" --meta "$RUN/meta.pcd" --class all \
  --md "$OUT/eval/43_livemeta_all.md" --json "$OUT/eval/43_livemeta_all.json" >/dev/null
[ -f "$RUN/objects/objects.csv" ] && "$LTM" eval objects --sim "$OUT/sim" --objects "$RUN/objects" --aligned "$RUN/aligned" \
  --md "$OUT/eval/44_objects.md" --json "$OUT/eval/44_objects.json" >/dev/null
rm -rf "$OUT/snapshots" && mkdir -p "$OUT/snapshots"
for s in "${NAMES[@]}"; do
  [ -f "$RUN/changes/$s/static_map.pcd" ] && ln -f "$RUN/changes/$s/static_map.pcd" "$OUT/snapshots/$s.pcd"
done
"$LTM" eval storage --path "$OUT/snapshots" --path "$RUN/map.ltmap" \
  --md "$OUT/eval/50_storage.md" --json "$OUT/eval/50_storage.json" >/dev/null
"$LTM" map log --store "$RUN/map.ltmap" > "$OUT/eval/51_map_log.txt"
{ echo "## LT-map log"; echo; echo '```'; cat "$OUT/eval/51_map_log.txt"; echo '```'; } > "$OUT/eval/51_map_log.md"

step "6/6 pictures and report"
TRAJ=(); for s in "${NAMES[@]}"; do
  [ -f "$RUN/aligned/$s/poses_world.txt" ] && TRAJ+=(--poses "$RUN/aligned/$s/poses_world.txt")
done
STATIC=(); for s in "${NAMES[@]}"; do
  [ -f "$RUN/changes/$s/static_map.pcd" ] && STATIC+=(--cloud "$RUN/changes/$s/static_map.pcd")
done
"$LTM" render "${STATIC[@]}" "${TRAJ[@]}" --color-by session --out "$OUT/renders/01_aligned_sessions.png"
CHG=(--cloud "$RUN/changes/${NAMES[0]}/static_map.pcd")
for f in "$RUN"/changes/pair_*/{nd_weak,nd_strong,pd_weak,pd_strong}.pcd; do [ -f "$f" ] && CHG+=(--cloud "$f"); done
"$LTM" render "${CHG[@]}" --color-by class --out "$OUT/renders/02_changes.png"
"$LTM" render --cloud "$RUN/live.pcd" --color-by class --out "$OUT/renders/03_live_map.png"
"$LTM" render --cloud "$RUN/meta.pcd" --color-by class --out "$OUT/renders/04_meta_map.png"
"$LTM" render --cloud "$RUN/restored_${NAMES[0]}.pcd" --cloud "$RUN/changes/${NAMES[0]}/static_map.pcd" \
  --color-by session --out "$OUT/renders/05_restored_vs_real.png"
[ -f "$RUN/objects/objects.ply" ] && "$LTM" render --cloud "$RUN/changes/${NAMES[0]}/static_map.pcd" \
  --cloud "$RUN/objects/objects.ply" --color-by class --out "$OUT/renders/06_objects.png"
# The 3D viewer: its browser test on this store writes the screenshot (chromium headless).
VIEW_SHOT="$OUT/renders/07_viewer.png"
node web/test/view_test.mjs --exe "$LTM" --store "$RUN/map.ltmap" --screenshot "$VIEW_SHOT" | tail -n 4
cat > "$OUT/eval/60_viewer.md" <<EOF_VIEW
## 3D viewer

\`$LTM view --store $RUN/map.ltmap\`, then open http://127.0.0.1:8080/ : the map in 3D with a session
slider (the map as of each session, by the store's rollback), the meta map, each session's changes
and coverage (new territory), the trajectories and the changed objects (click: fly to it, its box,
change and sessions). Level of detail: the whole map at a coarse voxel first, then finer voxels for
the 32 m tiles near the camera (down to 0.1 m) within a 2 M-point budget.
EOF_VIEW

ITEMS=(--item "$RUN/run_report.md")
for f in "$OUT"/eval/*.md; do ITEMS+=(--item "$f"); done
ITEMS+=(--item "$OUT/renders/01_aligned_sessions.png::Aligned sessions (LT-SLAM world poses) over each session's HD-free map, colored by session"
        --item "$OUT/renders/02_changes.png::Changes: PD strong/weak (blue), ND strong/weak (orange) over the central static map"
        --item "$OUT/renders/03_live_map.png::Live map: latest state, all PD"
        --item "$OUT/renders/04_meta_map.png::Meta map: strong PD only, seen-through space carved"
        --item "$OUT/renders/05_restored_vs_real.png::Rollback: the first session restored from the latest map (session 0 color) vs its own HD-free map")
[ -f "$OUT/renders/06_objects.png" ] && ITEMS+=(--item "$OUT/renders/06_objects.png::Objects parsed from strong ND / PD by Euclidean clustering")
ITEMS+=(--item "$VIEW_SHOT::ltmapper view (the browser test's screenshot): the map at an object's session with that session's changes, the object's box")
"$LTM" report --out "$OUT/report" --title "ltmapper demo: simulated city block, ${#NAMES[@]} sessions" "${ITEMS[@]}"
echo
echo "demo finished in $(( $(date +%s) - T0 )) s. Open $OUT/report.html (or read $OUT/report.md)."
