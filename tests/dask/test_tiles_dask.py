#!/usr/bin/env python3
"""`ltmapper tiles` on a local Dask cluster of 2 worker processes (python/ltmapper_dask.py).

The merged maps equal the local run's bytes; and again when one worker is killed (SIGKILL, with
its tile job) in the middle of a tile: Dask reruns that tile, nothing half-written is merged.
A pair's LD plan over its sessions' HD tiles runs on the cluster too: the same pair clouds.
Runs under pytest or as a script (exit code 77 = skipped: python3-distributed is not installed).
Needs LTM_EXE (the ltmapper executable) and LTM_SOURCE_DIR (the source tree).
"""
import filecmp
import json
import os
import stat
import subprocess
import sys
import tempfile

EXE = os.environ.get("LTM_EXE", "ltmapper")
SRC = os.environ.get("LTM_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))
sys.path.insert(0, os.path.join(SRC, "python"))
import ltmapper_dask  # noqa: E402

# A tiny drive: 30 keyframes 2 m apart, 32 x 512 beams; range 40 m and 40 m tiles: about a dozen tiles.
SIM_YAML = "route:\n  sessions: 1\n  keyframes: 30\n  keyframe_spacing_m: 2.0\nlidar:\n  beams: 32\n  columns: 512\n"
SETS = ["--set", "sensor.max_range_m=40", "--set", "submap_radius_m=30", "--set", "tiles.edge_m=40"]
MAPS = ("static_map.pcd", "hd_map.pcd")


def ltmapper(*args):
    subprocess.run([EXE, *args, "--quiet"], check=True)


LD_CLOUDS = ("nd_strong.pcd", "nd_weak.pcd", "pd_strong.pcd", "pd_weak.pcd", "pd_unobserved.pcd", "nd_residue.pcd",
             "pd_residue.pcd")


def make_sessions(work, sessions=1):
    """The simulated sessions' folders and true world poses: [(session, poses), ...]."""
    with open(os.path.join(work, "sim.yaml"), "w", encoding="utf-8") as f:
        f.write(SIM_YAML.replace("sessions: 1", f"sessions: {sessions}"))
    ltmapper("sim", "--config", os.path.join(work, "sim.yaml"), "--out", os.path.join(work, "sim"), "--threads", "2")
    return [(os.path.join(work, "sim", "sessions", f"session_{s:02d}"),
             os.path.join(work, "sim", "truth", f"session_{s:02d}", "poses_world.txt")) for s in range(sessions)]


def plan(work, name, session, poses):
    plan_dir = os.path.join(work, name)
    ltmapper("tiles", "plan", session, "--poses", poses, *SETS, "--out", plan_dir)
    return plan_dir


def killing_exe(work, tile):
    """ltmapper, except that the first job of `tile` is killed with its worker process 0.1 s in
    (jobs take about 0.2 s here), leaving a half-written part as a job killed between its writes
    would: a truncated static_map.pcd and no tile.json."""
    path = os.path.join(work, "ltmapper_killing_worker.sh")
    marker = os.path.join(work, "worker_killed")
    with open(path, "w", encoding="utf-8") as f:
        f.write(f"""#!/bin/sh
if [ "$1 $2 $4 $5" = "tiles run --tile {tile}" ] && mkdir "{marker}" 2>/dev/null; then
  part="$3/parts/$(printf tile_%06d {tile})"
  mkdir -p "$part" && printf 'VERSION .7\nFIELDS x' > "$part/static_map.pcd"
  "{EXE}" "$@" & job=$!
  sleep 0.1
  kill -9 $job $PPID
  exit 1
fi
exec "{EXE}" "$@"
""")
    os.chmod(path, os.stat(path).st_mode | stat.S_IXUSR)
    return path, marker


def same_outputs(a, b):
    for name in MAPS:
        assert filecmp.cmp(os.path.join(a, name), os.path.join(b, name), shallow=False), f"{name} differs: {a} {b}"
    with open(os.path.join(a, "report.json"), encoding="utf-8") as fa, open(os.path.join(b, "report.json"), encoding="utf-8") as fb:
        ra, rb = json.load(fa), json.load(fb)
    for key in ("tiles", "map_points", "candidates", "reverted", "removed", "dilated", "removed_per_resolution"):
        assert ra[key] == rb[key], f"report.json {key}: {ra[key]} != {rb[key]}"


def test_dask_cluster_equals_local_run_even_when_a_worker_dies():
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        import pytest
        pytest.skip("python3-distributed is not installed (scripts/install-deps.sh installs it)")
    with tempfile.TemporaryDirectory(prefix="ltm_dask_") as work:
        session, poses = make_sessions(work)[0]
        local = plan(work, "plan_local", session, poses)
        ltmapper("tiles", "run", local, "--threads", "2")
        ltmapper("tiles", "merge", local, "--out", os.path.join(work, "out_local"))
        n = ltmapper_dask.tile_count(local)
        assert n >= 4, f"{n} tiles: the scenario must span several tiles"
        with LocalCluster(n_workers=2, processes=True, threads_per_worker=1, dashboard_address=None) as cluster, \
                Client(cluster) as client:
            dask_plan = plan(work, "plan_dask", session, poses)
            ltmapper_dask.run_plan(client, dask_plan, os.path.join(work, "out_dask"), EXE)
            same_outputs(os.path.join(work, "out_local"), os.path.join(work, "out_dask"))

            exe, marker = killing_exe(work, n // 2)
            kill_plan = plan(work, "plan_kill", session, poses)
            ltmapper_dask.run_plan(client, kill_plan, os.path.join(work, "out_kill"), exe)
            assert os.path.isdir(marker), "the worker was not killed"
            same_outputs(os.path.join(work, "out_local"), os.path.join(work, "out_kill"))


def test_pair_ld_on_dask_equals_local_run():
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        import pytest
        pytest.skip("python3-distributed is not installed (scripts/install-deps.sh installs it)")
    with tempfile.TemporaryDirectory(prefix="ltm_dask_ld_") as work:
        hd = []
        for s, (session, poses) in enumerate(make_sessions(work, 2)):
            hd.append(plan(work, f"hd{s}", session, poses))
            ltmapper("tiles", "run", hd[-1], "--threads", "2")
        ld = os.path.join(work, "ld")
        ltmapper("tiles", "ld-plan", "--central", hd[0], "--query", hd[1], "--out", ld)
        n = ltmapper_dask.tile_count(ld)
        assert n >= 2, f"{n} LD tiles: the scenario must span several"
        with LocalCluster(n_workers=2, processes=True, threads_per_worker=1, dashboard_address=None) as cluster, \
                Client(cluster) as client:
            ltmapper_dask.run_plan(client, ld, os.path.join(work, "pair_dask"), EXE)
        ltmapper("tiles", "run", ld, "--threads", "2", "--force")
        ltmapper("tiles", "merge", ld, "--out", os.path.join(work, "pair_local"))
        for name in LD_CLOUDS:
            a, b = os.path.join(work, "pair_local", name), os.path.join(work, "pair_dask", name)
            assert filecmp.cmp(a, b, shallow=False), f"{name} differs: {a} {b}"


if __name__ == "__main__":
    try:
        import distributed  # noqa: F401
    except ImportError:
        print("SKIP: python3-distributed is not installed (scripts/install-deps.sh installs it)")
        sys.exit(77)
    test_dask_cluster_equals_local_run_even_when_a_worker_dies()
    print("ok: Dask (2 worker processes, one killed mid-tile) == local run")
    test_pair_ld_on_dask_equals_local_run()
    print("ok: a pair's LD tiles on Dask == local run")
