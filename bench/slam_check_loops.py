#!/usr/bin/env python3
"""Checks LT-SLAM loops against simulator truth: an accepted loop whose measured relative pose is
more than --max-error-m / --max-error-deg from the true one is a false loop.
usage: bench/slam_check_loops.py SIM_DIR ALIGNED_DIR"""
import argparse, csv, math, os, sys

# Rigid transforms as (R, t): R a 3x3 list of rows, t a 3-list (no numpy needed).
def kitti(path):
    out = []
    for line in open(path):
        v = [float(x) for x in line.split()]
        if len(v) == 12:
            out.append(([v[0:3], v[4:7], v[8:11]], [v[3], v[7], v[11]]))
    return out

def inv(T):
    R, t = T
    Rt = [[R[j][i] for j in range(3)] for i in range(3)]
    return (Rt, [-sum(Rt[i][k] * t[k] for k in range(3)) for i in range(3)])

def mul(A, B):
    Ra, ta = A
    Rb, tb = B
    R = [[sum(Ra[i][k] * Rb[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
    return (R, [sum(Ra[i][k] * tb[k] for k in range(3)) + ta[i] for i in range(3)])

ap = argparse.ArgumentParser()
ap.add_argument("sim"); ap.add_argument("aligned")
ap.add_argument("--max-error-m", type=float, default=1.0)
ap.add_argument("--max-error-deg", type=float, default=3.0)
ap.add_argument("--dump", help="write every registered candidate with its error against the truth (CSV)")
a = ap.parse_args()
truth = {}
def T(name):
    if name not in truth:
        truth[name] = kitti(os.path.join(a.sim, "truth", name, "poses_world.txt"))
    return truth[name]
def quat_to_R(x, y, z, w):
    return [[1-2*(y*y+z*z), 2*(x*y-z*w), 2*(x*z+y*w)],
            [2*(x*y+z*w), 1-2*(x*x+z*z), 2*(y*z-x*w)],
            [2*(x*z-y*w), 2*(y*z+x*w), 1-2*(x*x+y*y)]]

rows = list(csv.DictReader(open(os.path.join(a.aligned, "loops.csv"))))
dump = csv.writer(open(a.dump, "w")) if a.dump else None
if dump:
    dump.writerow(["pair", "kf_a", "kf_b", "source", "inlier_ratio", "inlier_rms_m", "error_m", "error_deg", "wrong", "accepted", "status"])
stats = {}
worst_t = worst_r = 0.0
for r in rows:
    if r["fitness"] == "-1":
        continue
    sa, sb = r["pair"].split("-")
    true_rel = mul(inv(T(sa)[int(r["kf_a"])]), T(sb)[int(r["kf_b"])])
    z = (quat_to_R(*(float(r[k]) for k in ("qx", "qy", "qz", "qw"))),
         [float(r[k]) for k in ("tx", "ty", "tz")])
    E = mul(inv(z), true_rel)
    et = math.sqrt(sum(x * x for x in E[1]))
    tr = E[0][0][0] + E[0][1][1] + E[0][2][2]
    er = math.degrees(math.acos(max(-1.0, min(1.0, (tr - 1) / 2))))
    wrong = et > a.max_error_m or er > a.max_error_deg
    acc = r["accepted"] == "1"
    if dump:
        dump.writerow([r["pair"], r["kf_a"], r["kf_b"], r["source"], r["inlier_ratio"], r["inlier_rms_m"],
                       "%.3f" % et, "%.3f" % er, int(wrong), int(acc), r["status"]])
    s = stats.setdefault(r["source"], [0, 0, 0, 0])  # accepted, accepted wrong, rejected, rejected wrong
    s[0 if acc else 2] += 1
    s[1 if acc else 3] += wrong
    if acc:
        worst_t, worst_r = max(worst_t, et), max(worst_r, er)
false_acc = 0
for src, (acc, accw, rej, rejw) in sorted(stats.items()):
    print(f"{src:6s}: accepted {acc} (false: {accw}), rejected {rej} (of which wrong: {rejw})")
    false_acc += accw
print(f"accepted loops: worst error vs truth {worst_t:.3f} m, {worst_r:.3f} deg "
      f"(false = error > {a.max_error_m} m or {a.max_error_deg} deg)")
print("FALSE LOOPS ACCEPTED: %d" % false_acc)
sys.exit(1 if false_acc else 0)
