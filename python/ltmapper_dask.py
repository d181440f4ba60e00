#!/usr/bin/env python3
"""Run an `ltmapper tiles` plan on Dask distributed: one task per tile, then the merge.

    ltmapper tiles plan SESSION --poses POSES --out PLAN
    python3 python/ltmapper_dask.py PLAN --out OUT [--scheduler tcp://HOST:8786 | --local-workers N]

An LD plan of a pair (`ltmapper tiles ld-plan --central PLAN_C --query PLAN_Q --out LDPLAN`, once
every HD tile of both sessions is done) runs the same way: its merge writes the pair's clouds.

Each task runs the `ltmapper` executable (`tiles run PLAN --tile N`) in a subprocess, so the
workers need the executable and a shared file system holding the plan folder and the session.
A tile job writes its parts under temporary names and its tile.json last: a task that fails, or
whose worker dies, is run again (Dask reschedules a dead worker's tasks; `--retries` more tries
for a failed job), and a tile already done is skipped. The merge runs as one more task once every
tile is done; its output equals `ltmapper tiles run PLAN` + `tiles merge` on one machine.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import uuid


def tile_count(plan_dir):
    """The number of tiles of the plan in plan_dir (its plan.json)."""
    path = os.path.join(plan_dir, "plan.json")
    try:
        with open(path, encoding="utf-8") as f:
            plan = json.load(f)
    except (OSError, ValueError) as e:
        raise RuntimeError(f"{path}: cannot read the tile plan: {e}") from e
    if plan.get("format") not in ("ltmapper tile plan", "ltmapper LD tile plan") or not isinstance(plan.get("tiles"), list):
        raise RuntimeError(f"{path}: not a tile plan")
    return len(plan["tiles"])


def _ltmapper(exe, args):
    """Runs `exe args...`; raises RuntimeError with its output when it fails."""
    proc = subprocess.run([exe, *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"{exe} {' '.join(args)} exited with {proc.returncode}:\n{proc.stdout}")
    return proc.stdout


def run_tile(exe, plan_dir, tile, threads):
    """One tile's job (skipped by ltmapper when the tile is done). Returns the tile number."""
    _ltmapper(exe, ["tiles", "run", plan_dir, "--tile", str(tile), "--threads", str(threads), "--quiet"])
    return tile


def merge(exe, plan_dir, out_dir, tiles):
    """The reduce: every tile's parts into out_dir (`tiles` only orders it after the tile tasks)."""
    _ltmapper(exe, ["tiles", "merge", plan_dir, "--out", out_dir, "--quiet"])
    return out_dir


def run_plan(client, plan_dir, out_dir, exe="ltmapper", threads=1, retries=3):
    """Submits every tile of the plan and the merge to a dask.distributed Client; returns out_dir."""
    plan_dir, out_dir = os.path.abspath(plan_dir), os.path.abspath(out_dir)
    run = uuid.uuid4().hex[:8]  # fresh task keys: a rerun of the driver reruns (or skips) the jobs
    tiles = [
        client.submit(run_tile, exe, plan_dir, t, threads, key=f"ltmapper-tile-{t}-{run}", retries=retries, pure=False)
        for t in range(tile_count(plan_dir))
    ]
    done = client.submit(merge, exe, plan_dir, out_dir, tiles, key=f"ltmapper-merge-{run}", retries=retries, pure=False)
    return done.result()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("plan_dir", help="plan folder of `ltmapper tiles plan` or `tiles ld-plan`")
    ap.add_argument("--out", required=True, help="output folder of the merge (static_map.pcd, hd_map.pcd, report.json; "
                    "an LD plan: the pair's clouds)")
    where = ap.add_mutually_exclusive_group()
    where.add_argument("--scheduler", help="address of a running dask-scheduler (tcp://HOST:8786)")
    where.add_argument("--local-workers", type=int, default=2, help="else a local cluster of this many worker processes")
    ap.add_argument("--exe", default=shutil.which("ltmapper") or "ltmapper", help="the ltmapper executable (on every worker)")
    ap.add_argument("--threads", type=int, default=1, help="threads per tile job (match the workers' cores)")
    ap.add_argument("--retries", type=int, default=3, help="more tries for a tile job that fails")
    a = ap.parse_args(argv)
    from distributed import Client, LocalCluster  # Debian: python3-distributed

    if a.scheduler:
        with Client(a.scheduler) as client:
            out = run_plan(client, a.plan_dir, a.out, a.exe, a.threads, a.retries)
    else:
        with LocalCluster(n_workers=a.local_workers, processes=True, threads_per_worker=1) as cluster, Client(cluster) as client:
            out = run_plan(client, a.plan_dir, a.out, a.exe, a.threads, a.retries)
    print(f"ltmapper_dask: {tile_count(a.plan_dir)} tiles merged into {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
