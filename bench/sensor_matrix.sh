#!/usr/bin/env bash
# The sensor matrix: for every config/scenarios/*.yaml (or the ones given), simulate it, run HD
# removal (LT-removert on the true world poses, default params: no sensor key set) on each
# session and score it against the point-wise truth. Prints one table, worst SA first.
#   usage: bench/sensor_matrix.sh [--ltmapper BIN] [--removert-config F] [--out DIR] [scenario.yaml ...]
#   (BIN runs the removert and eval steps, so an older build can be compared on the same data)
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
SIMBIN="$ROOT/build/apps/ltmapper"
LTM="$SIMBIN"
RCFG="$ROOT/config/params_ltremovert.yaml"
OUT="$ROOT/out/sensor_matrix"
SCEN=()
while [ $# -gt 0 ]; do
  case "$1" in
    --ltmapper) LTM="$2"; shift 2 ;;
    --removert-config) RCFG="$2"; shift 2 ;;
    --out) OUT="$2"; shift 2 ;;
    *) SCEN+=("$1"); shift ;;
  esac
done
[ ${#SCEN[@]} -gt 0 ] || SCEN=("$ROOT"/config/scenarios/*.yaml)
mkdir -p "$OUT"
ROWS="$OUT/rows.txt"
: > "$ROWS"
for yaml in "${SCEN[@]}"; do
  name="$(basename "$yaml" .yaml)"
  sim="$OUT/$name/sim"
  [ -f "$sim/truth/objects.csv" ] || { rm -rf "$sim"; "$SIMBIN" sim --config "$yaml" --out "$sim" --quiet >/dev/null; }
  for sdir in "$sim"/sessions/session_*; do
    s="$(basename "$sdir")"
    ch="$OUT/$name/changes_$s"
    rm -rf "$ch"
    kf=$(ls "$sdir/Scans" | wc -l)
    # CPU seconds and peak RSS of the HD removal (one session alone: no LD pair).
    /usr/bin/time -f "%U %S %M" -o "$OUT/$name/time_$s.txt" \
      "$LTM" removert --config "$RCFG" --sessions "$sdir" --poses "$sim/truth/$s/poses_world.txt" --out "$ch" --quiet >/dev/null 2>"$OUT/$name/removert_$s.log"
    "$LTM" eval hd --sim "$sim" --changes "$ch" --session "$s" --truth-frame world --json "$OUT/$name/hd_$s.json" --quiet >/dev/null
    read -r user sys rss < "$OUT/$name/time_$s.txt"
    python3 - "$OUT/$name/hd_$s.json" "$name" "$s" "$kf" "$user" "$sys" "$rss" >> "$ROWS" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
def find(o, k):
    if isinstance(o, dict):
        if k in o and not isinstance(o[k], (dict, list)): return o[k]
        for v in o.values():
            r = find(v, k)
            if r is not None: return r
    if isinstance(o, list):
        for v in o:
            r = find(v, k)
            if r is not None: return r
    return None
sa, da, sep = find(j, "sa"), find(j, "da"), find(j, "da_separable")
name, s, kf, user, sys_, rss = sys.argv[2:8]
cpu = float(user) + float(sys_)
sep = "n/a" if sep is None else f"{100*sep:.2f}"
print(f"{100*sa:.2f} | {name} | {s} | {100*da:.2f} | {sep} | {cpu/int(kf):.3f} | {int(rss)//1024}")
PY
  done
done
# DA separable: over the HD points farther than 0.1 m from every static truth point (eval hd's
# "hd near static" split: wheels and feet on the road count as kept while the road is kept).
echo "| SA % | scenario | session | DA % | DA % separable | HD CPU s/kf | peak MB |"
echo "|---:|---|---|---:|---:|---:|---:|"
sort -n "$ROWS" | awk -F' \\| ' '{printf "| %s | %s | %s | %s | %s | %s | %s |\n", $1, $2, $3, $4, $5, $6, $7}'
