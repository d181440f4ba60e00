#!/usr/bin/env python3
"""LT-map's object stage alone over kept scenario matrix runs: for every row folder that
bench/scenario_matrix.py --keep left (ROW/sim, ROW/run/map.ltmap, ROW/run/aligned), or a `make demo`
output (out/demo), run `ltmapper map objects` on a copy of the row's store (the row stays as it was)
and `ltmapper eval objects`, then print one table, worst object precision first:

  row | objects found / truth (precision) [observable found / truth] | moves found / truth, linked |
  clusters reported as moved (ends of a move among them) | mean IoU of the truth objects a cluster overlaps

A change to the object rules is measured on every row in about 30 s on 2 cores, against LT-SLAM and
LT-removert outputs that stay fixed (a full matrix takes about 15 min).

usage: bench/objects_matrix.py [--ltmapper BIN] [--out DIR] [--map-config F] [--baseline DIR] ROW [ROW ...]
  e.g. bench/objects_matrix.py --out /tmp/objects /tmp/matrix/* out/demo
  --baseline DIR: the --out of an earlier run over the same rows (e.g. main's binary); then each
  row also says what changed: SAME (every cluster and every truth object's IoU, and objects.csv
  byte for byte), or the truth objects whose IoU moved, and the clusters only one run holds; a
  column only this run's objects.csv holds is named, and the rest compared without it.
  The sensor of each row is read from its last session's scans (object_sensor_step_deg: 0).
  Exit status 0 even when a row misses a target: this prints figures, the tests judge.
"""
import argparse
import csv
import filecmp
import glob
import json
import os
import shutil
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "bench"))
from benchrun import timed  # noqa: E402
from scenario_matrix import eval_objects, objects_cell  # noqa: E402


def run_row(ltm, row, out, map_config):
    """The object stage and its evaluation on a copy of the row's store; returns eval's objects JSON."""
    store = os.path.join(row, "run", "map.ltmap")
    sessions = sorted(glob.glob(os.path.join(row, "sim", "sessions", "session_*")))
    if not os.path.exists(store) or not sessions:
        raise RuntimeError("%s: no run/map.ltmap or sim/sessions (not a kept matrix row)" % row)
    shutil.rmtree(out, ignore_errors=True)
    os.makedirs(out)
    copy = os.path.join(out, "map.ltmap")
    shutil.copyfile(store, copy)
    objects = os.path.join(out, "objects")
    timed([ltm, "map", "objects", "--store", copy, "--out", objects, "--session", sessions[-1],
           "--config", map_config, "--quiet"], os.path.join(out, "objects.log"))
    return eval_objects(ltm, os.path.join(row, "sim"), objects, os.path.join(row, "run", "aligned"),
                        os.path.join(out, "objects.json"))


def summary(name, o):
    """One table row's figures from eval objects' JSON."""
    moves = [m for m in o["moved"] if m["name"] == "all"][0]
    ious = [t["best_iou"] for t in o["objects"] if t["scored"] and t["best_cluster"] >= 0]
    return {
        "name": name, "precision": o["precision"] if o["clusters"] else 1.0,
        "objects": objects_cell(o),
        "moves": "%d/%d, %d" % (moves["found"], moves["truth_moves"], moves["linked"]),
        "moved": "%d (%d)" % (moves["reported"], moves["true_reported"]),
        "iou": "%.3f" % (sum(ious) / len(ious)) if ious else "-",
        "counts": (moves["found"], moves["truth_moves"], moves["reported"], moves["true_reported"], ious),
    }


def clusters(o):
    """A run's clusters as comparable tuples: pair, change, points, best truth object, IoU."""
    return sorted((c["pair"], c["change"], c["points"], c["best_truth"], round(c["best_iou"], 3))
                  for c in o["clusters_scored"])


def changes(out, base):
    """What differs between this run's row folder and the baseline's: a list of lines, [] = the same."""
    mine, theirs = [load_objects(d) for d in (out, base)]
    iou = {(t["pair"], t["id"]): t["best_iou"] for t in theirs["objects"]}
    lines = ["truth %s/%d IoU %.3f -> %.3f" % (t["pair"], t["id"], iou.get((t["pair"], t["id"]), 0.0), t["best_iou"])
             for t in mine["objects"] if abs(t["best_iou"] - iou.get((t["pair"], t["id"]), 0.0)) > 1e-9]
    a, b = clusters(mine), clusters(theirs)
    lines += ["cluster only here: %s" % (c,) for c in a if c not in b]
    lines += ["cluster only in the baseline: %s" % (c,) for c in b if c not in a]
    csvs = [os.path.join(d, "objects", "objects.csv") for d in (out, base)]
    if not lines and not filecmp.cmp(*csvs, shallow=False):
        mine_csv, theirs_csv = [read_csv(f) for f in csvs]
        added = [c for c in mine_csv[0] if c not in theirs_csv[0]]
        common = [c for c in mine_csv[0] if c in theirs_csv[0]]
        if added:
            lines.append("objects.csv columns only here: %s" % ", ".join(added))
        if columns(mine_csv, common) != columns(theirs_csv, common):
            lines.append("objects.csv differs (same clusters and IoUs)")
    return lines


def read_csv(path):
    """A CSV file as its header (a list) and its rows (lists)."""
    with open(path, newline="") as f:
        table = list(csv.reader(f))
    return table[0], table[1:]


def columns(table, names):
    """The rows of a read_csv table, each cut to the named columns in that order."""
    at = [table[0].index(n) for n in names]
    return [[row[k] for k in at] for row in table[1]]


def load_objects(row_out):
    with open(os.path.join(row_out, "objects.json")) as f:
        return json.load(f)["objects"]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ltmapper", default=os.path.join(ROOT, "build", "apps", "ltmapper"))
    ap.add_argument("--out", default="/tmp/ltmapper_objects_matrix")
    ap.add_argument("--map-config", default=os.path.join(ROOT, "config", "params_ltmap.yaml"))
    ap.add_argument("--baseline", help="--out of an earlier run over the same rows: print what changed")
    ap.add_argument("rows", nargs="+")
    a = ap.parse_args()
    rows, skipped, diffs = [], [], []
    for k, row in enumerate(a.rows):
        name = os.path.basename(os.path.normpath(row))
        try:
            out = os.path.join(a.out, "%02d_%s" % (k, name))  # rows of two matrices may share a name
            rows.append(summary(name, run_row(a.ltmapper, row, out, a.map_config)))
            if a.baseline:
                base = os.path.join(a.baseline, os.path.basename(out))
                lines = (changes(out, base) if os.path.exists(os.path.join(base, "objects.json"))
                         else ["no row %s in the baseline" % base])
                diffs.append("%s: %s" % (name, "SAME" if not lines else "\n  ".join(["changed"] + lines)))
        except RuntimeError as e:
            skipped.append("%s: skipped: %s" % (row, str(e).splitlines()[0]))
    rows.sort(key=lambda r: r["precision"])
    print("| row | objects found (precision) [observable] | moves found, linked | reported moved (true) | mean IoU |")
    print("|---|---|---|---|---:|")
    for r in rows:
        print("| %s | %s | %s | %s | %s |" % (r["name"], r["objects"], r["moves"], r["moved"], r["iou"]))
    found = sum(r["counts"][0] for r in rows)
    truth = sum(r["counts"][1] for r in rows)
    reported = sum(r["counts"][2] for r in rows)
    true = sum(r["counts"][3] for r in rows)
    ious = [x for r in rows for x in r["counts"][4]]
    print("\nall rows: moves found %d of %d; %d clusters reported as moved, %d of them ends of a move; "
          "mean IoU %.3f over %d truth objects" % (found, truth, reported, true,
                                                   sum(ious) / max(len(ious), 1), len(ious)))
    if diffs:
        print("\nagainst %s:" % a.baseline)
        print("\n".join(diffs))
    for line in skipped:
        print(line)


if __name__ == "__main__":
    main()
