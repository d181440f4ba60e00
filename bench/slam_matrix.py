#!/usr/bin/env python3
"""LT-SLAM alignment matrix (issue 15): seeds x {2 sessions of 120 keyframes, 3 of 300, 5 of 150 with
strong drift} x sensors. Per run: simulate, `ltmapper slam` with default parameters, then against
the truth: which sessions had to align (>= --min-near keyframes within --near-m of another
session's true path), which aligned, which aligned to a wrong place (inter-session consistency
RMSE over 1 m, or a false loop accepted), the worst consistency, the joint ATE next to the drifted
input's, and LT-SLAM's CPU seconds. Prints one table, worst row first.

usage: bench/slam_matrix.py [--ltmapper BIN] [--out DIR] [--seeds 1-20] [--configs 2x120,3x300,5x150d]
                            [--sensors uniform,hdl32e,os1-128] [--keep]
"""
import argparse
import json
import math
import os
import re
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "bench"))
from benchrun import timed  # noqa: E402
CONFIGS = {  # name: (sessions, keyframes, strong drift)
    "2x120": (2, 120, False),
    "3x300": (3, 300, False),
    "5x150d": (5, 150, True),
}
# The strong drift: 2 % scale, 3 % step noise, 0.15 deg/sqrt(m) of yaw.
STRONG_DRIFT = {"scale": "0.02", "translation": "0.03", "yaw_deg": "0.15"}


def scenario_lidar(name):
    """The lidar keys of config/scenarios/NAME.yaml (a sensor no preset names, e.g. the rosette), or None."""
    path = os.path.join(ROOT, "config", "scenarios", name + ".yaml")
    if not os.path.exists(path):
        return None
    keys, inside = {}, False
    for line in open(path):
        if not line.startswith(" "):
            inside = line.startswith("lidar:")
        elif inside and ":" in line:
            k, v = line.split("#")[0].split(":", 1)
            keys["  " + k.strip()] = v.strip()
    return keys


def sim_yaml(sessions, keyframes, drift, preset, seed):
    text = open(os.path.join(ROOT, "config", "params_sim.yaml")).read()
    lidar = scenario_lidar(preset)
    subs = {"seed": str(seed), "  sessions": str(sessions), "  keyframes": str(keyframes)}
    subs.update(lidar if lidar is not None else {"  preset": preset})
    if drift:
        subs.update({"  " + k: v for k, v in STRONG_DRIFT.items()})
    for key, val in subs.items():
        text, n = re.subn(r"(?m)^(%s:)\s*[^\s#]+" % re.escape(key), r"\g<1> " + val, text, count=1)
        if n != 1:
            raise RuntimeError("params_sim.yaml has no '%s:' line" % key.strip())
    return text


def positions(path):
    out = []
    for line in open(path):
        v = line.split()
        if len(v) == 12:
            out.append((float(v[3]), float(v[7]), float(v[11])))
    return out


def must_align(sim, names, near_m, min_near):
    """Query sessions with at least min_near keyframes within near_m of another session's true path."""
    paths = {n: positions(os.path.join(sim, "truth", n, "poses_world.txt")) for n in names}
    need = set()
    for q in names[1:]:
        others = [p for n in names if n != q for p in paths[n]]
        near = sum(1 for p in paths[q] if any(math.dist(p, o) <= near_m for o in others))
        if near >= min_near:
            need.add(q)
    return need


def one_run(a, cfg_name, preset, seed):
    sessions, keyframes, drift = CONFIGS[cfg_name]
    out = os.path.join(a.out, "%s_%s_s%d" % (cfg_name, preset, seed))
    sim = os.path.join(out, "sim")
    os.makedirs(out, exist_ok=True)
    if not os.path.exists(os.path.join(sim, "truth", "objects.csv")):
        y = os.path.join(out, "sim.yaml")
        with open(y, "w") as f:
            f.write(sim_yaml(sessions, keyframes, drift, preset, seed))
        timed([a.ltmapper, "sim", "--config", y, "--out", sim, "--quiet"], os.path.join(out, "sim.log"))
    names = sorted(os.listdir(os.path.join(sim, "sessions")))
    aligned = os.path.join(out, "aligned")
    subprocess.call(["rm", "-rf", aligned])
    cpu, _, _ = timed([a.ltmapper, "slam", "--sessions"] + [os.path.join(sim, "sessions", n) for n in names] +
                ["--out", aligned, "--quiet"], os.path.join(out, "slam.log"))
    j, jd = os.path.join(out, "traj.json"), os.path.join(out, "traj_drifted.json")
    timed([a.ltmapper, "eval", "traj", "--sim", sim, "--aligned", aligned, "--json", j, "--quiet"], j + ".log")
    timed([a.ltmapper, "eval", "traj", "--sim", sim, "--drifted", "--json", jd, "--quiet"], jd + ".log")
    t, td = json.load(open(j))["traj"], json.load(open(jd))["traj"]
    chk = subprocess.run([sys.executable, os.path.join(ROOT, "bench", "slam_check_loops.py"), sim, aligned],
                         capture_output=True, text=True).stdout
    false_loops = int(re.search(r"FALSE LOOPS ACCEPTED: (\d+)", chk).group(1)) if "FALSE LOOPS" in chk else -1
    need = must_align(sim, names, a.near_m, a.min_near)
    done = {n for n in names[1:] if os.path.exists(os.path.join(aligned, n, "poses_world.txt"))}
    cons = {c["name"]: c["error"] for c in t.get("consistency_sessions", [])}
    wrong = {n for n in done if n in cons and cons[n]["trans_m"]["rmse"] is not None and cons[n]["trans_m"]["rmse"] > 1.0}
    worst_m = max([cons[n]["trans_m"]["rmse"] or 0.0 for n in done if n in cons] or [float("nan")])
    worst_deg = max([cons[n]["rot_deg"]["rmse"] or 0.0 for n in done if n in cons] or [float("nan")])
    if not a.keep:
        # Only the true poses are read again: drop the scans and the point-wise truth (~0.4 GB a session).
        truth = os.path.join(sim, "truth")
        heavy = [os.path.join(truth, n, "labels") for n in names] + \
            [os.path.join(truth, d) for d in os.listdir(truth) if d.startswith("pair_")]
        subprocess.call(["rm", "-rf", os.path.join(sim, "sessions")] + heavy)
    return dict(cfg=cfg_name, sensor=preset, seed=seed, need=len(need), missed=len(need - done), aligned=len(done),
                queries=len(names) - 1, wrong=len(wrong), false_loops=false_loops, worst_m=worst_m,
                worst_deg=worst_deg, ate=t["ate"]["trans_m"]["rmse"], ate_in=td["ate"]["trans_m"]["rmse"], cpu=cpu)


def seeds(spec):
    out = []
    for part in spec.split(","):
        lo, _, hi = part.partition("-")
        out += list(range(int(lo), int(hi or lo) + 1))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ltmapper", default=os.path.join(ROOT, "build", "apps", "ltmapper"))
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "slam_matrix"))
    ap.add_argument("--seeds", default="1-20")
    ap.add_argument("--configs", default=",".join(CONFIGS))
    ap.add_argument("--sensors", default="uniform,hdl32e,os1-128", help="lidar.preset values (uniform = the default 64), or the name of a "
                    "config/scenarios/ file whose lidar keys to use (rosette)")
    ap.add_argument("--near-m", type=float, default=5.0)
    ap.add_argument("--min-near", type=int, default=20)
    ap.add_argument("--keep", action="store_true", help="keep the simulated scans")
    a = ap.parse_args()
    rows = []
    for seed in seeds(a.seeds):
        for c in a.configs.split(","):
            for p in a.sensors.split(","):
                try:
                    rows.append(one_run(a, c, p, seed))
                    r = rows[-1]
                    print("done %s %s seed %d: %d/%d must-align aligned, %d wrong, %d false loops, worst consistency "
                          "%.3f m / %.3f deg, %.0f s CPU" % (
                              c, p, seed, r["need"] - r["missed"], r["need"], r["wrong"], r["false_loops"], r["worst_m"],
                              r["worst_deg"], r["cpu"]), file=sys.stderr, flush=True)
                except RuntimeError as e:
                    print("run %s %s seed %d: %s" % (c, p, seed, e), file=sys.stderr, flush=True)
    print("| config | sensor | seed | must align: aligned / total | other queries aligned | wrong places | false loops | "
          "worst consistency m / deg | joint ATE m (drifted input) | LT-SLAM CPU s |")
    print("|---|---|---:|---|---:|---:|---:|---|---|---:|")
    key = lambda r: (-r["missed"], -r["wrong"], -r["false_loops"], -(r["worst_m"] if r["worst_m"] == r["worst_m"] else 9))
    for r in sorted(rows, key=key):
        print("| %s | %s | %d | %d / %d | %d | %d | %d | %.3f / %.3f | %.3f (%.1f) | %.1f |" % (
            r["cfg"], r["sensor"], r["seed"], r["need"] - r["missed"], r["need"], r["aligned"] - (r["need"] - r["missed"]),
            r["wrong"], r["false_loops"], r["worst_m"], r["worst_deg"], r["ate"], r["ate_in"], r["cpu"]))
    n = len(rows)
    print("\n%d runs: %d sessions had to align, %d missed, %d aligned to a wrong place, %d false loops accepted" % (
        n, sum(r["need"] for r in rows), sum(r["missed"] for r in rows), sum(r["wrong"] for r in rows),
        sum(max(0, r["false_loops"]) for r in rows)))


if __name__ == "__main__":
    main()
