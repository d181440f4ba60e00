#!/usr/bin/env python3
"""Thread scaling and serial fraction of the three stages (issue 18): each stage runs alone as its
own command (`ltmapper slam`, `ltmapper removert --aligned`, `ltmapper map integrate`) at every
thread count asked for, on the same simulated sessions, and one table is printed:

  stage | threads | wall s | CPU s | CPU / wall | speedup vs 1 thread | serial fraction

and a "pipeline" row, the three stages one after the other (their walls and CPU summed).

Serial fraction (Amdahl), two estimates: from one run at N threads, s = (N * wall / CPU - 1) / (N - 1)
(the share of the work that ran on one core, if CPU time is the work); and from the 1-thread run,
s = (N * T_N / T_1 - 1) / (N - 1). The first needs no 1-thread run and is what the issue's "CPU vs
wall" asks for; the second also counts threads that wait. The map stage is integrated from scratch
(`map integrate` creates the store) and computes the objects too.

usage: bench/stage_scaling.py [--ltmapper BIN] [--out DIR] [--threads 1,2,...] [--scenario YAML]
                              [--keyframes N]
  The scenario (default config/scenarios/default64.yaml) is simulated once into OUT/sim; an OUT/sim
  already there (e.g. a link to the demo's out/demo/sim) is used as it is.
"""
import argparse
import glob
import os
import re
import shutil
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "bench"))
from benchrun import timed  # noqa: E402


def simulate(ltm, yaml, out, keyframes):
    sim = os.path.join(out, "sim")
    if os.path.exists(os.path.join(sim, "truth", "objects.csv")):
        return sim
    text = open(yaml).read()
    if keyframes:
        text = re.sub(r"(?m)^(  keyframes:)\s*\d+", r"\g<1> %d" % keyframes, text)
    cfg = os.path.join(out, "sim_config.yaml")
    with open(cfg, "w") as f:
        f.write(text)
    timed([ltm, "sim", "--config", cfg, "--out", sim, "--quiet"], os.path.join(out, "sim.log"))
    return sim


def run_stages(ltm, sim, out, threads):
    """Each stage alone at `threads`; returns {stage: (cpu s, wall s)}."""
    d = os.path.join(out, "t%d" % threads)
    shutil.rmtree(d, ignore_errors=True)
    os.makedirs(d)
    sessions = sorted(glob.glob(os.path.join(sim, "sessions", "session_*")))
    aligned, changes, store = os.path.join(d, "aligned"), os.path.join(d, "changes"), os.path.join(d, "map.ltmap")
    t = ["--threads", str(threads)]  # each log keeps the stage's own phase timings
    res = {}
    cpu, _, wall = timed([ltm, "slam", "--sessions"] + sessions + ["--out", aligned] + t, os.path.join(d, "slam.log"))
    res["LT-SLAM"] = (cpu, wall)
    cpu, _, wall = timed([ltm, "removert", "--aligned", aligned, "--out", changes] + t, os.path.join(d, "removert.log"))
    res["LT-removert"] = (cpu, wall)
    cpu, _, wall = timed([ltm, "map", "integrate", "--store", store, "--aligned", aligned, "--changes", changes,
                          "--sessions", os.path.join(sim, "sessions")] + t, os.path.join(d, "map.log"))
    res["LT-map"] = (cpu, wall)
    for stage, (cpu, wall) in res.items():  # as it goes, so that a run cut short still tells something
        print("%d threads: %s %.1f s wall, %.1f s CPU" % (threads, stage, wall, cpu), file=sys.stderr, flush=True)
    return res


STAGES = ("LT-SLAM", "LT-removert", "LT-map")


def serial_from_cpu(n, cpu, wall):
    return None if n < 2 or cpu <= 0 else (n * wall / cpu - 1.0) / (n - 1.0)


def serial_from_t1(n, t1, tn):
    return None if n < 2 or not t1 else (n * tn / t1 - 1.0) / (n - 1.0)


def fmt(v, digits=2):
    return "-" if v is None else "%.*f" % (digits, v)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ltmapper", default=os.path.join(ROOT, "build", "apps", "ltmapper"))
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "stage_scaling"))
    ap.add_argument("--threads", default="1,%d" % os.cpu_count())
    ap.add_argument("--scenario", default=os.path.join(ROOT, "config", "scenarios", "default64.yaml"))
    ap.add_argument("--keyframes", type=int, default=0)
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    sim = simulate(a.ltmapper, a.scenario, a.out, a.keyframes)
    counts = sorted({int(x) for x in a.threads.split(",")})
    results = {n: run_stages(a.ltmapper, sim, a.out, n) for n in counts}
    print("machine: %d cores; sessions: %s" % (os.cpu_count(), os.path.realpath(sim)))
    print("| stage | threads | wall s | CPU s | CPU / wall | speedup vs 1 thread | serial fraction (CPU vs wall) "
          "| serial fraction (vs 1 thread) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for n in counts:  # the whole pipeline: the three stages one after the other
        results[n]["pipeline"] = tuple(sum(results[n][s][i] for s in STAGES) for i in (0, 1))
    for stage in STAGES + ("pipeline",):
        t1 = results[1][stage][1] if 1 in results else None
        for n in counts:
            cpu, wall = results[n][stage]
            print("| %s | %d | %.1f | %.1f | %.2f | %s | %s | %s |" % (
                stage, n, wall, cpu, cpu / wall if wall else 0.0, fmt(t1 / wall if t1 else None),
                fmt(serial_from_cpu(n, cpu, wall)), fmt(serial_from_t1(n, t1, wall))))


if __name__ == "__main__":
    main()
