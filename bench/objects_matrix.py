#!/usr/bin/env python3
"""LT-map's object stage alone over kept scenario matrix runs: for every row folder that
bench/scenario_matrix.py --keep left (ROW/sim, ROW/run/map.ltmap, ROW/run/aligned), or a `make demo`
output (out/demo), run `ltmapper map objects` on a copy of the row's store (the row stays as it was)
and `ltmapper eval objects`, then print one table, worst object precision first:

  row | objects found / truth (precision) [observable found / truth] | moves found / truth, linked |
  clusters reported as moved (ends of a move among them) | mean IoU of the truth objects a cluster overlaps

A change to the object rules is measured on every row in about 30 s on 2 cores, against LT-SLAM and
LT-removert outputs that stay fixed (a full matrix takes about 15 min).

usage: bench/objects_matrix.py [--ltmapper BIN] [--out DIR] [--map-config F] ROW [ROW ...]
  e.g. bench/objects_matrix.py --out /tmp/objects /tmp/matrix/* out/demo
  The sensor of each row is read from its last session's scans (object_sensor_step_deg: 0).
  Exit status 0 even when a row misses a target: this prints figures, the tests judge.
"""
import argparse
import glob
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


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ltmapper", default=os.path.join(ROOT, "build", "apps", "ltmapper"))
    ap.add_argument("--out", default="/tmp/ltmapper_objects_matrix")
    ap.add_argument("--map-config", default=os.path.join(ROOT, "config", "params_ltmap.yaml"))
    ap.add_argument("rows", nargs="+")
    a = ap.parse_args()
    rows, skipped = [], []
    for k, row in enumerate(a.rows):
        name = os.path.basename(os.path.normpath(row))
        try:
            out = os.path.join(a.out, "%02d_%s" % (k, name))  # rows of two matrices may share a name
            rows.append(summary(name, run_row(a.ltmapper, row, out, a.map_config)))
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
    for line in skipped:
        print(line)


if __name__ == "__main__":
    main()
