#!/usr/bin/env python3
"""Where one truth object's change went: for a kept matrix row (ROW/sim, ROW/run, as
bench/scenario_matrix.py --keep leaves it) or a `make demo` output (out/demo), and one changed
truth object of a pair, print

  the truth object (class, the session it exists in, its change points: truth PD / ND, strong /
  weak) and `eval objects`' verdict on it (ROW/eval/objects.json, when there);
  where each session of the pair was: its nearest keyframe (the run's poses) and range;
  LD against the truth, point by point: each truth change point of the object, in the run's world
  frame, with the LD class of the run's nearest change point within the match distance (none:
  no change point there: LD called it the same surface, or it is not in the map);
  the object stage: every object (objects.csv) and rejected cluster (rejected.csv, with its reason)
  whose box overlaps the object's;
  with --beams, where the beams of the session that judges each change point went (the query's
  for ND, the central's for PD: its scans, the run's poses, the beam table estimated from its
  scans): per truth class x LD class, how many points a beam passed within ld.beam_tol_m of and
  then met nothing (sky) or returned beyond the point (beyond), else ended on it (hit), else only
  ended in front of it (blocked), or none passed (none). The beam truth calls sky and beyond seen
  through; this tells an LD class that missed them from a point no beam reached.

It answers the first question about a missed object (LD's classes, a residue, or a cluster the
rules rejected, and why) without a debugger. Needs the Python bindings (`import ltmapper`: build/
python, or PYTHONPATH) and numpy.

usage: bench/trace_object.py [--sim DIR] [--run DIR] [--eval FILE] [--pair CC_QQ] [--beams] [--json] ROW OBJECT
  e.g. bench/trace_object.py /tmp/matrix/os1-64 0
  --sim / --run / --eval: other places than ROW/sim, ROW/run, ROW/eval/objects.json.
  --pair: the pair whose truth holds the object (default: the first pair the truth has that holds it).
  --beams: also the beams' verdicts (slower: reads every scan of the judging sessions).
  --json: the same as one JSON object.
Exit status 2 with a message naming the file when an input is missing or the object is not a
changed object of the pair.
"""
import argparse
import csv
import glob
import json
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "build", "python"))
import ltmapper  # noqa: E402

# The LD clouds of a pair folder (docs/FORMATS.md), named as LT-removert writes them.
LD_CLOUDS = ("pd_strong", "pd_weak", "pd_unobserved", "pd_residue", "nd_strong", "nd_weak", "nd_residue")
# The change classes of the truth's labelled clouds (core::PointClass, named by the bindings).
CHANGE_CLASSES = tuple(n for n in ltmapper.CLASS_NAMES if n.startswith(("pd_", "nd_")))
MATCH_DIST_M = ltmapper.EvalConfig().get("ld.match_dist_m")  # eval ld's match distance [m]
NEAR_BOX_M = 1.0  # LD points read around the object's box [m]
BEAM_TOL_M = ltmapper.RemovertConfig().get("ld.beam_tol_m")  # a beam this close to a point passed it [m]
# A beam's verdict on a point, strongest evidence first (beams()); the first two are the beam
# truth's "seen through".
BEAM_VERDICTS = ("sky", "beyond", "hit", "blocked", "none")
SKY, BEYOND, HIT, BLOCKED, NONE = range(len(BEAM_VERDICTS))
SEEN_THROUGH = BEAM_VERDICTS[:2]
# The objects.csv / rejected.csv columns a trace prints (docs/FORMATS.md).
CLUSTER_COLUMNS = ("id", "session", "class", "change", "partner", "points", "length", "width", "height",
                   "height_above_ground", "clearance", "range_m", "observed_fraction", "twin_fraction",
                   "attached_fraction", "box_seen_fraction")


class TraceError(Exception):
    pass


def need(path):
    if not os.path.exists(path):
        raise TraceError("%s: not found" % path)
    return path


def truth_pairs(sim):
    return sorted(os.path.basename(p)[len("pair_"):] for p in glob.glob(os.path.join(sim, "truth", "pair_*")))


def truth_points(sim, pair, obj):
    """The object's labelled change points in the truth frame: (points (N,3), class names), or None."""
    ply = need(os.path.join(ltmapper.find_pair_dir(os.path.join(sim, "truth"), pair), "objects_changes.ply"))
    t = ltmapper.read_ply(ply)
    m = t["object"] == obj
    if not m.any():
        return None
    return t["points"][m, :3].astype(float), [ltmapper.CLASS_NAMES[int(c)] for c in t["cls"][m]]


def to_frame(T, p):
    return p @ T[:3, :3].T + T[:3, 3]


def nearest_ld(pair_dir, pts):
    """Per point, the LD class of the nearest change point within MATCH_DIST_M (or "none") and the
    LD points per class inside the points' box grown by NEAR_BOX_M."""
    lo, hi = pts.min(0) - NEAR_BOX_M, pts.max(0) + NEAR_BOX_M
    best = np.full(len(pts), np.inf)
    cls = np.array(["none"] * len(pts), dtype=object)
    around = {}
    for name in LD_CLOUDS:
        c = ltmapper.read_cloud(need(os.path.join(pair_dir, name + ".pcd")))[:, :3].astype(float)
        c = c[np.all((c >= lo) & (c <= hi), axis=1)]
        around[name] = int(len(c))
        for first in range(0, len(c), 2048):
            d = np.sqrt(((pts[:, None, :] - c[None, first:first + 2048, :]) ** 2).sum(-1)).min(1)
            better = (d <= MATCH_DIST_M) & (d < best)
            best[better], cls[better] = d[better], name
    return list(cls), around


def pair_sessions(sim, aligned, pair):
    """The pair's central and query: (session name, the run's world poses as `eval traj` reads them,
    or None where the run did not align it), by their positions among the sim's sessions."""
    names = ltmapper.sim_session_names(sim)
    est = {s["name"]: s["est"] for s in ltmapper.load_sim_trajectories(sim, aligned)["sessions"]}
    return [(names[int(k)], est.get(names[int(k)])) for k in pair.split("_")]


def sessions_near(pair, sessions, centroid):
    """Per session of the pair (pair_sessions): its keyframe nearest the object and range."""
    out = []
    for k, (_, poses) in zip(pair.split("_"), sessions):
        if poses is None:
            out.append({"session": k, "aligned": False})
            continue
        d = np.linalg.norm(poses[:, :3, 3] - centroid, axis=1)
        out.append({"session": k, "aligned": True, "nearest_keyframe": int(d.argmin()), "range_m": float(d.min())})
    return out


def overlapping(path, lo, hi, reason):
    """Rows of objects.csv / rejected.csv whose axis-aligned box overlaps [lo, hi]."""
    rows = []
    with open(need(path)) as f:
        for r in csv.DictReader(f):
            blo = np.array([float(r[k]) for k in ("min_x", "min_y", "min_z")])
            bhi = np.array([float(r[k]) for k in ("max_x", "max_y", "max_z")])
            if np.all(blo <= hi) and np.all(bhi >= lo):
                row = {k: r[k] for k in CLUSTER_COLUMNS if k in r}
                row["reason"] = r.get("reason", "") if reason else "accepted"
                rows.append(row)
    return rows


def eval_verdict(eval_json, pair, obj):
    if not eval_json or not os.path.exists(eval_json):
        return None
    with open(eval_json) as f:
        objects = json.load(f)["objects"]["objects"]
    for o in objects:
        if o["pair"] == pair and o["id"] == obj:
            return {k: o[k] for k in ("found", "scored", "best_cluster", "best_iou", "observed_share") if k in o}
    return None


def beam_views(scan, T, pts, elevations, az_half):
    """The verdict of one keyframe's beams (scan in its sensor frame, world pose T) on each point:
    index into BEAM_VERDICTS (NONE: no beam of the table passed within BEAM_TOL_M)."""
    r = np.linalg.norm(scan, axis=1)
    az = np.arctan2(scan[:, 1], scan[:, 0])
    el = np.arcsin(np.clip(scan[:, 2] / np.maximum(r, 1e-9), -1, 1))
    order = np.argsort(az)
    az, el, r = az[order], el[order], r[order]
    ps = (pts - T[:3, 3]) @ T[:3, :3]
    rp = np.linalg.norm(ps, axis=1)
    ep = np.arcsin(np.clip(ps[:, 2] / np.maximum(rp, 1e-9), -1, 1))
    ap = np.arctan2(ps[:, 1], ps[:, 0])
    out = np.full(len(pts), NONE)
    nearest = np.abs(elevations[None, :] - ep[:, None]).argmin(1)
    beam = elevations[nearest]
    # Each beam's returns: within half the gap to its nearer neighbour in the table.
    gaps = np.diff(elevations)
    half_gap = 0.5 * np.minimum(np.r_[np.inf, gaps], np.r_[gaps, np.inf])
    # Only points within the farthest return of this scan: beyond it, no return is no sign of free
    # space (the sensor's range is not in the scans).
    for i in np.where((rp * np.abs(np.sin(beam - ep)) <= BEAM_TOL_M) & (rp <= r.max(initial=0.0)))[0]:
        w = np.concatenate([np.arange(*np.searchsorted(az, [a - az_half, a + az_half]))
                            for a in (ap[i] - 2 * np.pi, ap[i], ap[i] + 2 * np.pi)])  # azimuth wraps at +-pi
        near = r[w][np.abs(el[w] - beam[i]) <= half_gap[nearest[i]]]
        if len(near) == 0:
            out[i] = SKY
        elif near.min() < rp[i] - BEAM_TOL_M:
            out[i] = BLOCKED
        elif near.min() <= rp[i] + BEAM_TOL_M:
            out[i] = HIT
        else:
            out[i] = BEYOND
    return out


def beams(sim, sessions, pts, truth_cls):
    """Per point, the strongest verdict (BEAM_VERDICTS) over the keyframes of the session that
    judges it (pair_sessions): the pair's query for ND points, its central for PD points."""
    (central, central_poses), (query, query_poses) = sessions
    best = np.full(len(pts), NONE)
    for judge, poses, mine in ((query, query_poses, np.array([c.startswith("nd_") for c in truth_cls])),
                               (central, central_poses, np.array([c.startswith("pd_") for c in truth_cls]))):
        if not mine.any() or poses is None:
            continue
        session_dir = need(os.path.join(sim, "sessions", judge))
        scans = [np.asarray(c)[:, :3].astype(float) for c in ltmapper.load_session(session_dir).scans()]
        model = ltmapper.estimate_sensor(scans)
        if not model.ring_based or model.beams < 2 or model.azimuth_step_deg <= 0.0:
            raise TraceError("%s: --beams needs a sensor with rings and a known azimuth step (%s)" % (
                session_dir, model.describe()))
        elevations = np.radians(np.sort(np.asarray(model.elevations_deg, dtype=float)))
        az_half = np.radians(model.azimuth_step_deg)
        for scan, T in zip(scans, poses):
            v = beam_views(scan, T, pts[mine], elevations, az_half)
            best[mine] = np.minimum(best[mine], v)
    return [BEAM_VERDICTS[b] for b in best]


def trace(sim, run, obj, pair=None, eval_json=None, with_beams=False):
    """The trace of truth object `obj` as a dict (see the module's docstring)."""
    pairs = [pair] if pair else truth_pairs(need(sim))
    found = None
    for p in pairs:
        found = truth_points(sim, p, obj)
        if found is not None:
            pair = p
            break
    if found is None:
        raise TraceError("%s: object %d is no changed object of pair %s" % (
            os.path.join(sim, "truth"), obj, ", ".join(pairs) or "(none)"))
    pts_truth, truth_cls = found
    aligned = need(os.path.join(run, "aligned"))
    sessions = pair_sessions(sim, aligned, pair)
    pts = to_frame(ltmapper.truth_to_estimate_frame(sim, aligned), pts_truth)
    ld_cls, around = nearest_ld(need(ltmapper.find_pair_dir(os.path.join(run, "changes"), pair)), pts)
    confusion, heights = {}, {}
    for t, l, z in zip(truth_cls, ld_cls, pts[:, 2] - pts[:, 2].min()):
        confusion.setdefault(t, {}).setdefault(l, 0)
        confusion[t][l] += 1
        heights.setdefault("%s %s" % (t, l), []).append(float(z))
    lo, hi = pts.min(0), pts.max(0)
    objects_dir = os.path.join(run, "objects")
    beam_table = None
    if with_beams:
        beam_table = {}
        for t, l, b in zip(truth_cls, ld_cls, beams(sim, sessions, pts, truth_cls)):
            row = beam_table.setdefault("%s %s" % (t, l), {})
            row[b] = row.get(b, 0) + 1
    return {
        "object": obj, "pair": pair, "change_points": len(pts),
        "box_world": {"min": lo.round(3).tolist(), "max": hi.round(3).tolist()},
        "eval": eval_verdict(eval_json, pair, obj),
        "sessions": sessions_near(pair, sessions, pts.mean(0)),
        "ld": {"truth_x_ld": confusion, "ld_points_around": around,
               "heights_m": {k: [round(min(v), 2), round(max(v), 2)] for k, v in heights.items()}},
        "objects": overlapping(os.path.join(objects_dir, "objects.csv"), lo, hi, False) +
                   overlapping(os.path.join(objects_dir, "rejected.csv"), lo, hi, True),
        "beams": beam_table,
    }


def print_trace(t):
    print("truth object %d, pair %s: %d change points, world box %s .. %s" % (
        t["object"], t["pair"], t["change_points"], t["box_world"]["min"], t["box_world"]["max"]))
    print("eval objects: %s" % (t["eval"] if t["eval"] is not None else "(no eval/objects.json)"))
    for s in t["sessions"]:
        print("session %s: %s" % (s["session"], "not aligned" if not s["aligned"] else
                                  "nearest keyframe %d at %.1f m" % (s["nearest_keyframe"], s["range_m"])))
    print("LD, truth class x LD class of the nearest change point within %.2f m (heights above the object's"
          " lowest change point, m):" % MATCH_DIST_M)
    h = t["ld"]["heights_m"]
    for tc, row in sorted(t["ld"]["truth_x_ld"].items()):
        print("  %-10s %s" % (tc, "  ".join("%s %d [%.2f-%.2f]" % ((lc, n) + tuple(h["%s %s" % (tc, lc)]))
                                            for lc, n in sorted(row.items(), key=lambda kv: -kv[1]))))
    print("LD points within %.1f m of its box: %s" % (NEAR_BOX_M, "  ".join(
        "%s %d" % kv for kv in t["ld"]["ld_points_around"].items() if kv[1])))
    if t["beams"] is not None:
        print("beams of the judging session within %.2f m of each point, truth class x LD class: %s" % (
            BEAM_TOL_M, " / ".join(BEAM_VERDICTS)))
        for k, row in sorted(t["beams"].items()):
            print("  %-20s %s" % (k, " / ".join(str(row.get(v, 0)) for v in BEAM_VERDICTS)))
    print("clusters whose box overlaps it:" if t["objects"] else "no cluster's box overlaps it")
    for o in t["objects"]:
        print("  " + ", ".join("%s %s" % kv for kv in o.items()))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("row")
    ap.add_argument("object", type=int)
    ap.add_argument("--sim")
    ap.add_argument("--run")
    ap.add_argument("--eval", dest="eval_json")
    ap.add_argument("--pair")
    ap.add_argument("--beams", action="store_true")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    sim = a.sim or os.path.join(a.row, "sim")
    run = a.run or os.path.join(a.row, "run")
    try:
        t = trace(sim, run, a.object, a.pair, a.eval_json or os.path.join(a.row, "eval", "objects.json"), a.beams)
    except (TraceError, ltmapper.Error) as e:
        print("trace_object: %s" % e, file=sys.stderr)
        return 2
    if a.json:
        print(json.dumps(t, indent=1))
    else:
        print_trace(t)
    return 0


if __name__ == "__main__":
    sys.exit(main())
