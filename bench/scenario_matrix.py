#!/usr/bin/env python3
"""The whole pipeline over the scenario matrix (issue 14): for every config/scenarios/*.yaml (or the
ones given) simulate it, run `ltmapper run` with default parameters (no sensor or resolution key
set: LT-SLAM poses, LT-removert, LT-map), score every stage against the simulator's truth, and print
one table, worst HD SA first:

  scenario | sessions aligned | SA %% per session | DA %% per session (before the multi-session cleanup)
  [over the HD points farther than 0.1 m from every static truth point] | inter-session RMSE m / deg |
  LD PD P/R, ND P/R per pair {recall over the changed objects' points alone, PD/ND} <recall over the
  separable truth, PD/ND: farther than the match distance from what the other session sampled> and strong / weak correct,
  against the beam truth (and the exact-ray truth) | changed objects found (precision) [found among the observable ones, eval objects' slice] | HD wall s/kf | run wall s | peak MB of the run

usage: bench/scenario_matrix.py [--ltmapper BIN] [--out DIR] [--keep] [--keyframes N] [--seed S] [--true-poses]
                               [--reuse DIR] [--baseline DIR] [--slam-config F] [--removert-config F] [--map-config F]
                               [scenario.yaml ...]
  --true-poses: the simulator's true world poses instead of LT-SLAM's (`ltmapper run --poses`), the
  second pose source of issue 17's acceptance; "consistency" is then 0.
  --keyframes sets route.keyframes of every scenario (e.g. 40 for a quick pass), --seed the seed.
  --slam-config / --removert-config / --map-config go to `ltmapper run` (e.g. a slam YAML with
  `registration: {steps: true}`); without them every stage runs with its defaults.
  A scenario's sim folder is reused when a finished sim of the same config is there (delete --out to redo).
  --reuse DIR: the --out of an earlier --keep run over the same scenarios (its seed and pose source):
  each row's simulation is hard-linked from there and its LT-SLAM output (run/aligned) copied, and
  `ltmapper run --from removert` runs LT-removert and LT-map with --ltmapper: a change to those stages
  measured on the same poses as the earlier binary's rows (compare them with --baseline), in
  about two thirds of the time of full runs (--seed and --keyframes are the kept run's, not given again).
  --baseline DIR: the --out of an earlier run over the same scenarios (e.g. main's binary with --reuse
  on the same kept run): after the table, each row's figures that differ from that run's, eval file by
  eval file (HD SA / DA, LD P / R of PD and ND and the changed objects' recall, objects found and
  precision), or "same".
  Exit status 0 even when a row misses a target: this prints figures, the tests judge.
"""
import argparse
import glob
import json
import os
import re
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "bench"))
from benchrun import timed  # noqa: E402


def load(path):
    with open(path) as f:
        return json.load(f)


def simulate(ltm, yaml, sim, keyframes, seed):
    """Simulates the scenario (route.keyframes replaced when given) unless the same config, simulated
    by the same code (`ltmapper --version` holds its code id), is there."""
    text = open(yaml).read()
    if keyframes:
        text, n = re.subn(r"(?m)^(  keyframes:)\s*\d+", r"\g<1> %d" % keyframes, text)
        if n != 1:
            raise RuntimeError("%s: no 'route: keyframes:' line to replace" % yaml)
    cfg = os.path.join(os.path.dirname(sim), "sim_config.yaml")
    version = subprocess.run([ltm, "--version"], capture_output=True, text=True).stdout.strip()
    want = text + "\n# seed %s\n# %s\n" % (seed, version)
    if os.path.exists(os.path.join(sim, "truth", "objects.csv")) and os.path.exists(cfg) and open(cfg).read() == want:
        return
    # The config under its own name is the mark of a finished sim: it is written to a temporary
    # name, simulated from there, and renamed only when the sim succeeded, so a killed or failed
    # run is simulated again instead of reused half-written.
    subprocess.call(["rm", "-rf", sim, cfg])
    pending = cfg + ".pending"
    with open(pending, "w") as f:
        f.write(want)
    cmd = [ltm, "sim", "--config", pending, "--out", sim, "--quiet"]
    if seed is not None:
        cmd += ["--seed", str(seed)]
    timed(cmd, sim + ".log")
    os.replace(pending, cfg)


def eval_objects(ltm, sim, objects, aligned, j):
    """`ltmapper eval objects` of an objects folder into the JSON file j; returns its "objects"."""
    timed([ltm, "eval", "objects", "--sim", sim, "--objects", objects, "--aligned", aligned, "--json", j, "--quiet"],
          j + ".log")
    return load(j)["objects"]


def objects_cell(o):
    """The table's objects cell: found / truth objects (precision) [found / truth among the observable]."""
    cell = "%d/%d (%s)" % (o["found"], o["truth_objects"], fmt(o["precision"]))
    ob = o.get("observable")
    if ob:
        cell += " [%d/%d]" % (ob["found"], ob["truth_objects"])
    return cell


def hd_wall_per_keyframe(changes):
    """HD removal wall seconds per keyframe (map + votes, all sessions) from changes/report.json
    (None when the run stopped before LT-removert)."""
    if not os.path.exists(os.path.join(changes, "report.json")):
        return None
    rep = load(os.path.join(changes, "report.json"))
    total_s = sum(s["seconds_map"] + s["seconds_votes"] for s in rep["sessions"])
    kf = sum(s["keyframes"] for s in rep["sessions"])
    return total_s / kf if kf else None


def evaluate(ltm, sim, out, names):
    """Every evaluator on one scenario's run; returns the row's figures."""
    runp, ev = os.path.join(out, "run"), os.path.join(out, "eval")
    subprocess.call(["rm", "-rf", ev])  # figures of an earlier run are never read as this one's
    os.makedirs(ev, exist_ok=True)
    aligned, changes = os.path.join(runp, "aligned"), os.path.join(runp, "changes")
    row = {"sa": [], "da": [], "da_own": [], "da_sep": [], "ld": [], "aligned": 0}
    for n in names:
        if os.path.exists(os.path.join(aligned, n, "poses_world.txt")):
            row["aligned"] += 1
    j = os.path.join(ev, "traj.json")
    timed([ltm, "eval", "traj", "--sim", sim, "--aligned", aligned, "--json", j, "--quiet"], j + ".log")
    c = load(j)["traj"]["consistency"]
    row["rmse_m"], row["rmse_deg"] = c["trans_m"]["rmse"], c["rot_deg"]["rmse"]
    for n in names:
        j = os.path.join(ev, "hd_%s.json" % n)
        if not os.path.isdir(os.path.join(changes, n)):
            continue
        timed([ltm, "eval", "hd", "--sim", sim, "--changes", changes, "--session", n, "--aligned", aligned,
             "--json", j, "--quiet"], j + ".log")
        h = load(j)["hd"]
        row["sa"].append(h["sa"])
        row["da"].append(h["da"])
        # DA over the HD points farther than hd_near_static_m from every static truth point: the
        # rest (wheels and feet on the road) count as kept while the static point under them is.
        row["da_sep"].append(h.get("da_separable"))
        # The session's own HD removal, before the multi-session cleanup.
        j = os.path.join(ev, "hd_%s_own.json" % n)
        timed([ltm, "eval", "hd", "--sim", sim, "--changes", changes, "--session", n, "--aligned", aligned,
             "--single-session", "--json", j, "--quiet"], j + ".log")
        row["da_own"].append(load(j)["hd"]["da"])
    for pdir in sorted(glob.glob(os.path.join(changes, "pair_*"))):
        pair = os.path.basename(pdir)[len("pair_"):]
        j = os.path.join(ev, "ld_%s.json" % pair)
        timed([ltm, "eval", "ld", "--sim", sim, "--changes", changes, "--pair", pair, "--aligned", aligned,
             "--truth-from-scans", "--json", j, "--quiet"], j + ".log")
        l = load(j)["ld"]
        je = os.path.join(ev, "ld_%s_exact_ray.json" % pair)
        timed([ltm, "eval", "ld", "--sim", sim, "--changes", changes, "--pair", pair, "--aligned", aligned,
             "--truth-from-scans", "--exact-ray", "--json", je, "--quiet"], je + ".log")
        le = load(je)["ld"]
        objs = [l.get(k, {}).get("recall") for k in ("pd_objects", "nd_objects")]
        sep = [l.get(k, {}).get("recall") for k in ("pd_separable", "nd_separable")]
        row["ld"].append((pair, l["pd"]["precision"], l["pd"]["recall"], l["nd"]["precision"], l["nd"]["recall"],
                          objs[0], objs[1], sep[0], sep[1], l["pd_strength"]["accuracy"], l["nd_strength"]["accuracy"],
                          le["pd_strength"]["accuracy"], le["nd_strength"]["accuracy"]))
    objects = os.path.join(runp, "objects")
    row["objects"] = None
    if os.path.exists(os.path.join(objects, "objects.csv")):
        row["objects"] = objects_cell(eval_objects(ltm, sim, objects, aligned, os.path.join(ev, "objects.json")))
    row["hd_s_kf"] = hd_wall_per_keyframe(changes)
    return row


def reuse_slam(kept, out):
    """A row of --reuse: the kept row's simulation hard-linked into `out` and its LT-SLAM output copied."""
    aligned = os.path.join(kept, "run", "aligned")
    if not os.path.isdir(aligned):
        raise RuntimeError("%s: no run/aligned (not a row of a --keep run)" % kept)
    for d in ("sim", "run"):
        subprocess.call(["rm", "-rf", os.path.join(out, d)])
    subprocess.check_call(["cp", "-al", os.path.join(kept, "sim"), os.path.join(out, "sim")])
    os.makedirs(os.path.join(out, "run"))
    subprocess.check_call(["cp", "-a", aligned, os.path.join(out, "run", "aligned")])


def scenario(ltm, yaml, out_root, keyframes, seed, keep, run_args, true_poses=False, reuse=None):
    name = os.path.splitext(os.path.basename(yaml))[0]
    out = os.path.join(out_root, name)
    sim = os.path.join(out, "sim")
    runp = os.path.join(out, "run")
    os.makedirs(out, exist_ok=True)
    if reuse:
        reuse_slam(os.path.join(reuse, name), out)
        run_args = run_args + ["--from", "removert"]
    else:
        simulate(ltm, yaml, sim, keyframes, seed)
        subprocess.call(["rm", "-rf", runp])
    sessions = sorted(glob.glob(os.path.join(sim, "sessions", "session_*")))
    names = [os.path.basename(s) for s in sessions]
    if true_poses:  # the second pose source: the simulator's true world poses (`run --poses`)
        run_args = run_args + ["--poses"] + [os.path.join(sim, "truth", n, "poses_world.txt") for n in names]
    log = os.path.join(out, "run.log")
    t0 = time.time()
    try:
        cpu, rss, wall = timed([ltm, "run", "--sessions"] + sessions + ["--out", runp] + run_args, log)
    except RuntimeError:
        # A run that aligned no query session stops after LT-SLAM (exit 1). It is a row of the
        # table all the same ("1/N" aligned, no LD): the drives may share no view (eval traj's
        # figures and the run's aligned/report.md tell), and a missing row would hide it. Told by
        # LT-SLAM's report (every query session not aligned), not by the log's wording.
        rep = os.path.join(runp, "aligned", "report.json")
        if not os.path.exists(rep):
            raise
        slam = load(rep)
        if any(x["aligned"] for x in slam["sessions"] if x["name"] != slam["central"]):
            raise
        cpu, rss, wall = None, None, time.time() - t0
    row = evaluate(ltm, sim, out, names)
    row.update(name=name, sessions=len(names), cpu=cpu, rss=rss, wall=wall)
    if not keep:  # the run's clouds are large; the figures are in eval/
        subprocess.call(["rm", "-rf"] + [os.path.join(runp, f) for f in ("changes", "map.ltmap", "live.pcd", "meta.pcd")])
    return row


def fmt(v, scale=1.0, digits=2):
    return "n/a" if v is None else ("%.*f" % (digits, v * scale))


def eval_figures(path):
    """The figures of one eval JSON that --baseline compares: {name: value}."""
    d = load(path)
    if "hd" in d:
        return {k: d["hd"].get(k) for k in ("sa", "da")}
    if "ld" in d:
        f = {}
        for k in ("pd", "nd"):
            f[k + " P"], f[k + " R"] = d["ld"][k]["precision"], d["ld"][k]["recall"]
        for k in ("pd_objects", "nd_objects"):
            f[k + " R"] = d["ld"][k]["recall"]
        return f
    if "objects" in d:
        return {k: d["objects"].get(k) for k in ("found", "clusters", "precision")}
    return {}


def print_changes(rows, out, baseline):
    """Per row: the eval figures (eval_figures) that differ from the same row of `baseline`."""
    show = lambda v: str(v) if isinstance(v, int) else fmt(v, 1, 5)
    print("\nChanges against %s:" % baseline)
    for r in sorted(rows, key=lambda r: r["name"]):
        ev, base_ev = os.path.join(out, r["name"], "eval"), os.path.join(baseline, r["name"], "eval")
        if not os.path.isdir(base_ev):
            print("- %s: not in the baseline" % r["name"])
            continue
        paths = sorted(glob.glob(os.path.join(ev, "*.json")))
        lines = [] if paths else ["no eval files in %s" % ev]
        for path in paths:
            base = os.path.join(base_ev, os.path.basename(path))
            if not os.path.exists(base):
                lines.append("%s: not in the baseline" % os.path.basename(path))
                continue
            a, b = eval_figures(base), eval_figures(path)
            diff = ["%s %s -> %s" % (k, show(a.get(k)), show(b[k])) for k in b if a.get(k) != b[k]]
            if diff:
                lines.append("%s: %s" % (os.path.basename(path), ", ".join(diff)))
        print("- %s: %s" % (r["name"], "; ".join(lines) if lines else "same"))


def print_table(rows):
    print(("| scenario | aligned | SA %% per session | DA %% per session (own removal) [separable] | consistency m / deg | "
          "LD pair: PD P/R, ND P/R {recall over changed objects PD/ND} <separable recall PD/ND>; strong/weak correct PD/ND, beam truth (exact-ray truth) | objects found (precision) [observable found] | HD wall s/kf (%d threads) | run wall s | peak MB |") % os.cpu_count())
    print("|---|---|---|---|---|---|---|---:|---:|---:|")
    for r in sorted(rows, key=lambda r: min(r["sa"]) if r["sa"] else -1):
        ld = "; ".join("%s: %s/%s, %s/%s {%s/%s} <%s/%s>; %s/%s (%s/%s)" % (
                           p, fmt(a), fmt(b), fmt(c), fmt(d), fmt(oa), fmt(ob), fmt(sa), fmt(sb), fmt(e), fmt(f), fmt(g),
                           fmt(h))
                       for p, a, b, c, d, oa, ob, sa, sb, e, f, g, h in r["ld"])
        obj = r["objects"] or "n/a"
        print("| %s | %d/%d | %s | %s | %s / %s | %s | %s | %s | %s | %s |" % (
            r["name"], r["aligned"], r["sessions"], " ".join(fmt(x, 100) for x in r["sa"]),
            " ".join("%s (%s) [%s]" % (fmt(x, 100), fmt(y, 100), fmt(z, 100))
                     for x, y, z in zip(r["da"], r["da_own"], r["da_sep"])),
            fmt(r["rmse_m"], 1, 3), fmt(r["rmse_deg"], 1, 3), ld or "-", obj,
            fmt(r["hd_s_kf"], 1, 3), fmt(r["wall"], 1, 0), fmt(r["rss"], 1, 0)))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ltmapper", default=os.path.join(ROOT, "build", "apps", "ltmapper"))
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "scenario_matrix"))
    ap.add_argument("--keyframes", type=int, default=0, help="route.keyframes of every scenario (0 = the scenario's)")
    ap.add_argument("--seed", type=int, default=None, help="simulator seed of every scenario (default: the scenario's)")
    ap.add_argument("--keep", action="store_true", help="keep each run's changes/, map store and live / meta maps")
    ap.add_argument("--reuse", default=None,
                    help="--out of an earlier --keep run: its simulations and LT-SLAM outputs, LT-removert on")
    ap.add_argument("--true-poses", action="store_true",
                    help="place the sessions by the simulator's true world poses (`ltmapper run --poses`) instead of "
                         "LT-SLAM's; LD's rotation tolerance is then measured at those poses")
    for stage in ("slam", "removert", "map"):
        ap.add_argument("--%s-config" % stage, default=None, help="`ltmapper run --%s-config` (default: none)" % stage)
    ap.add_argument("--baseline", default=None, help="--out of an earlier run over the same scenarios: print what changed")
    ap.add_argument("scenarios", nargs="*")
    a = ap.parse_args()
    run_args = []
    for stage in ("slam", "removert", "map"):
        f = getattr(a, "%s_config" % stage)
        if f:
            run_args += ["--%s-config" % stage, os.path.abspath(f)]
    yamls = a.scenarios or sorted(glob.glob(os.path.join(ROOT, "config", "scenarios", "*.yaml")))
    if a.reuse and os.path.realpath(a.reuse) == os.path.realpath(a.out):
        ap.error("--reuse must name another folder than --out (its rows are read, --out's are replaced)")
    if a.reuse and (a.seed is not None or a.keyframes):
        ap.error("--reuse runs on the kept run's simulations: --seed and --keyframes are that run's")
    rows = []
    for y in yamls:
        try:
            rows.append(scenario(a.ltmapper, y, a.out, a.keyframes, a.seed, a.keep, run_args, a.true_poses, a.reuse))
            print("done %s (%.0f s)" % (rows[-1]["name"], rows[-1]["wall"]), file=sys.stderr, flush=True)
        except RuntimeError as e:
            print("scenario %s: %s" % (y, e), file=sys.stderr, flush=True)
    print_table(rows)
    if a.baseline:
        print_changes(rows, a.out, a.baseline)


if __name__ == "__main__":
    main()
