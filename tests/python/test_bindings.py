"""Tests of the Python bindings (`import ltmapper`) on a tiny simulated scenario.

Run by ctest (`python_bindings`: /usr/bin/python3 with PYTHONPATH=build/python), directly
(`PYTHONPATH=build/python python3 tests/python/test_bindings.py`) or with pytest.
"""
import atexit
import math
import os
import shutil
import sys
import tempfile
import time

import numpy as np

import ltmapper

SOURCE_DIR = os.environ.get(
    "LTM_SOURCE_DIR", os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))

_state = {}


def work():
    """A temporary directory with the tiny scenario simulated once (2 sessions x 10 keyframes)."""
    if "dir" not in _state:
        d = tempfile.mkdtemp(prefix="ltm_py_")
        atexit.register(shutil.rmtree, d, True)
        ltmapper.set_log_level("warn")
        cfg = ltmapper.SimConfig.tiny()
        cfg.route.sessions = 2
        cfg.route.keyframes = 10
        _state["dir"] = d
        _state["sim_report"] = ltmapper.simulate(cfg, os.path.join(d, "sim"), threads=2)
    return _state["dir"]


def sim_dir():
    return os.path.join(work(), "sim")


def session_dir(k):
    return os.path.join(sim_dir(), "sessions", "session_%02d" % k)


def truth_poses(k):
    return os.path.join(sim_dir(), "truth", "session_%02d" % k, "poses_world.txt")


def raises(exc, fn, *args, match=None, **kwargs):
    try:
        fn(*args, **kwargs)
    except exc as e:
        if match is not None:
            assert match in str(e), "expected %r in %r" % (match, str(e))
        return e
    raise AssertionError("%s did not raise %s" % (getattr(fn, "__name__", fn), exc.__name__))


# ----------------------------------------------------------------------------------- tests
def test_module():
    assert ltmapper.CLASS_NAMES[1] == "static" and len(ltmapper.CLASS_NAMES) == 7
    assert issubclass(ltmapper.Error, RuntimeError)
    raises(ValueError, ltmapper.set_log_level, "loud")


def test_simulate():
    work()
    r = _state["sim_report"]
    assert r["sessions"] == 2 and r["keyframes"] == 20 and r["points"] > 0
    assert ltmapper.sim_session_names(sim_dir()) == ["session_00", "session_01"]


def test_session():
    s = ltmapper.load_session(session_dir(0))
    assert s.name == "session_00" and len(s) == 10 and len(s.keyframes) == 10
    assert s.poses.shape == (10, 4, 4) and s.poses.dtype == np.float64
    np.testing.assert_allclose(s.poses[:, 3, :], np.tile([0, 0, 0, 1], (10, 1)))
    np.testing.assert_allclose(s.keyframes[3].pose, s.poses[3])
    # The simulator writes times.txt: keyframe timestamps increasing with the index.
    times = [k.time_s for k in s.keyframes]
    assert times[0] == 0.0 and all(b > a for a, b in zip(times, times[1:]))
    scan = s.scan(0)
    assert scan.dtype == np.float32 and scan.ndim == 2 and scan.shape[1] == 4 and len(scan) > 100
    np.testing.assert_array_equal(scan, s.keyframes[0].scan())
    np.testing.assert_array_equal(s.scan(-1), s.scans()[-1])
    assert list(s.indices) == [k.index for k in s.keyframes] and s.find(s.indices[2]) == 2
    assert len(s.odometry) == 9 and s.odometry[0]["T_from_to"].shape == (4, 4)
    raises(IndexError, s.scan, 10)
    assert "10" in ltmapper.inspect_session(session_dir(0))
    # A bad path raises ltmapper.Error carrying the C++ message (naming the path).
    e = raises(ltmapper.Error, ltmapper.load_session, os.path.join(work(), "missing"))
    assert "missing" in str(e)


def test_cloud_round_trip():
    rng = np.random.default_rng(1)
    a = rng.uniform(-50, 50, size=(1000, 4)).astype(np.float32)
    for fmt in ("binary", "ascii", "binary_compressed"):
        p = os.path.join(work(), "cloud_%s.pcd" % fmt)
        ltmapper.write_pcd(p, a, format=fmt)
        b = ltmapper.read_cloud(p)
        assert b.dtype == np.float32 and b.shape == (1000, 4)
        if fmt == "ascii":
            np.testing.assert_allclose(b, a, rtol=1e-6)
        else:
            np.testing.assert_array_equal(b, a)
    # (N,3) input gets intensity 0; KITTI .bin round trip.
    p = os.path.join(work(), "xyz.bin")
    ltmapper.write_kitti_bin(p, a[:, :3].astype(np.float64))
    b = ltmapper.read_cloud(p)
    np.testing.assert_array_equal(b[:, :3], a[:, :3])
    assert not b[:, 3].any()
    # Labelled PLY round trip.
    lab = {"points": a, "cls": np.full(1000, 3, np.uint8), "session": np.arange(1000, dtype=np.uint16) % 3,
           "object": np.arange(1000, dtype=np.int32) - 1}
    p = os.path.join(work(), "lab.ply")
    ltmapper.write_ply(p, lab)
    b = ltmapper.read_ply(p)
    for k in ("points", "cls", "session", "object"):
        np.testing.assert_array_equal(b[k], lab[k])
    raises(ValueError, ltmapper.write_pcd, p, np.zeros((5, 2)))
    raises(ltmapper.Error, ltmapper.read_cloud, os.path.join(work(), "nope.pcd"), match="nope.pcd")


def test_configs():
    c = ltmapper.RemovertConfig()
    d = c.to_dict()
    assert set(d) == set(c.keys()) and "hd.dilate_voxels" in d
    assert c.hd.dilate_voxels == d["hd.dilate_voxels"] == c.get("hd.dilate_voxels")
    c.hd.dilate_voxels = 1.0
    c.set("ld.weak_nd=false")
    c.set("sensor.model", "vlp16")
    assert c.to_dict()["hd.dilate_voxels"] == 1.0 and c.ld.weak_nd is False and c.sensor.model == "vlp16"
    raises(TypeError, setattr, c.ld, "weak_nd", 1)
    raises(ltmapper.Error, setattr, c, "submap_radius_m", -5.0)  # out of range: value kept
    assert c.submap_radius_m == d["submap_radius_m"]
    raises(AttributeError, getattr, c, "no_such_key")
    e = raises(ltmapper.Error, c.set, "hd.no_such_key=1")
    assert "no_such_key" in str(e)
    # YAML: the shipped params files load; an unknown key raises with the file and key named.
    for name, cls in (("params_ltslam.yaml", ltmapper.SlamConfig), ("params_ltremovert.yaml", ltmapper.RemovertConfig),
                      ("params_ltmap.yaml", ltmapper.MapConfig), ("params_eval.yaml", ltmapper.EvalConfig),
                      ("params_sim.yaml", ltmapper.SimConfig)):
        cfg = cls.from_yaml(os.path.join(SOURCE_DIR, "config", name))
        assert cfg.to_dict() == cls().to_dict() or name == "params_sim.yaml" or cfg.keys() == cls().keys()
    bad = os.path.join(work(), "bad.yaml")
    with open(bad, "w") as f:
        f.write("hd:\n  dilate_voxels: 1.0\n  bogus_key: 3\n")
    e = raises(ltmapper.Error, ltmapper.RemovertConfig.from_yaml, bad)
    assert "bogus_key" in str(e) and "bad.yaml" in str(e)
    # save_yaml / from_yaml round trip, dict constructor, copy.
    out = os.path.join(work(), "saved.yaml")
    c.save_yaml(out)
    assert ltmapper.RemovertConfig.from_yaml(out) == c
    m = ltmapper.MapConfig({"output_voxel_m": 0.0, "object_min_points": 5})
    assert m.output_voxel_m == 0.0 and m.object_min_points == 5
    m2 = m.copy()
    m2.output_voxel_m = 0.5
    assert m.output_voxel_m == 0.0
    raises(ltmapper.Error, ltmapper.MapConfig, {"bogus": 1})


def test_sensor():
    assert "vlp16" in ltmapper.sensor_presets()
    v = ltmapper.sensor_preset("vlp16")
    assert v.beams == 16 and v.to_dict()["beams"] == 16
    raises(ltmapper.Error, ltmapper.sensor_preset, "nope", match="vlp16")
    s = ltmapper.load_session(session_dir(0))
    est = ltmapper.estimate_sensor([s.scan(i) for i in range(3)])
    assert est.source == "estimated" and est.beams == 16, est.describe()
    # a ring sensor looks all around: every azimuth is in its view
    assert est.azimuth_half_fov_deg == 180.0 and est.in_azimuth_view(179.0) and est.in_azimuth_view(-90.0)
    assert est.to_dict()["azimuth_half_fov_deg"] == 180.0
    t = ltmapper.sensor_from_table([10.0, 0.0, -10.0])
    assert t.beams == 3


def test_remove_hd():
    s = ltmapper.load_session(session_dir(0))
    poses = ltmapper.read_kitti_poses(truth_poses(0))
    assert poses.shape == (10, 4, 4)
    r = ltmapper.remove_hd(ltmapper.RemovertConfig(), s, poses, threads=2)
    static, hd = r["static_map"], r["hd_map"]
    assert static.dtype == np.float32 and static.shape[1] == 4 and len(static) > 1000
    assert r["stats"]["map_points"] == len(static) + len(hd) and r["stats"]["removed"] > 0
    raises(ltmapper.Error, ltmapper.remove_hd, ltmapper.RemovertConfig(), s, poses[:5])
    m = ltmapper.build_session_map(ltmapper.RemovertConfig(), s, poses)
    assert len(m) == r["stats"]["map_points"]
    assert ltmapper.resolve_removert_sensor(ltmapper.RemovertConfig(), s).beams == 16


def test_stages_store_eval():
    """LT-SLAM -> LT-removert -> LT-map through the bindings, then the Store and the evaluators."""
    w = work()
    aligned, changes, store_path = os.path.join(w, "aligned"), os.path.join(w, "changes"), os.path.join(w, "m.ltmap")
    slam = ltmapper.run_slam(ltmapper.SlamConfig(), session_dir(0), [session_dir(1)], aligned, threads=2)
    assert [s["name"] for s in slam["sessions"]] == ["session_00", "session_01"]
    assert slam["sessions"][0]["aligned"] and slam["sessions"][0]["T_world_sensor"].shape == (10, 4, 4)
    assert "session_00" in ltmapper.aligned_sessions(aligned)
    # The tiny routes are too short for LT-SLAM to align session_01 reliably; the map stage gets
    # the true world poses in LT-SLAM's layout instead (the same frame LT-removert runs in below).
    truth_aligned = os.path.join(w, "aligned_truth")
    for k in (0, 1):
        d = os.path.join(truth_aligned, "session_%02d" % k)
        os.makedirs(d)
        ltmapper.write_kitti_poses(os.path.join(d, "poses_world.txt"), ltmapper.read_kitti_poses(truth_poses(k)))
        ltmapper.write_kitti_poses(os.path.join(d, "anchor.txt"), np.eye(4)[None])
    assert ltmapper.aligned_sessions(truth_aligned) == ["session_00", "session_01"]
    rem = ltmapper.run_removert(ltmapper.RemovertConfig(), [session_dir(0), session_dir(1)],
                                [truth_poses(0), truth_poses(1)], changes, threads=2)
    assert rem["sessions"] == ["session_00", "session_01"] and rem["pairs"] == [(0, 1)]
    assert rem["hd"][0]["map_points"] > 0
    static = ltmapper.read_cloud(os.path.join(changes, "session_00", "static_map.pcd"))
    assert len(static) > 1000
    steps = ltmapper.map_integrate(store_path, ltmapper.MapConfig(), truth_aligned, changes, threads=2)
    assert [s["name"] for s in steps] == ["central", "session_01"] and steps[0]["points"] > 0

    # object_sensor_step_deg: the tiny scenario's 16 beams over 40 deg (`ltmapper run` derives it)
    st = ltmapper.Store(store_path, ltmapper.MapConfig({"object_sensor_step_deg": 2.67}))
    assert st.session_names()[0] == "session_00" and st.latest_session == len(steps) - 1
    assert st.sessions()[0]["anchor"].shape == (4, 4) and st.keyframes()[0]["T_world_sensor"].shape == (4, 4)
    for k in range(st.latest_session + 1):
        m = st.map_at(k, voxel=0.0)
        assert m["points"].shape[1] == 4 and len(m["cls"]) == len(m["points"]) > 0
    live, meta = st.live(), st.meta()
    assert len(live["points"]) > 0 and len(meta["points"]) > 0
    assert len(st.map_at("session_00", box=((-5, -5, -5), (5, 5, 5)))["points"]) <= len(st.map_at(0)["points"])
    assert isinstance(st.objects(), list) and st.fsck()["ok"] and st.totals()["file_bytes"] > 0
    assert all(o["track"] <= o["id"] and o["exists_in"] in o["track_sessions"] for o in st.objects())
    assert all(o["partner"] < 0 or o["partner"] in o["move_candidates"] for o in st.objects())
    assert all(o["partner"] < 0 or o["alike_beside"] == 0 for o in st.objects())  # no move's end among its like
    assert all(o["hidden_length_m"] >= 0.0 for o in st.objects())  # how much longer than its box, unseen
    ch = st.step_changes(1, voxel=0.0)
    assert set(np.unique(ch["cls"])) <= {3, 4, 5, 6} and (ch["session"] == 1).all()
    kf = st.keyframes()[0]
    assert len(st.keyframe_cloud(kf["id"], 0)["points"]) == kf["base_points"] or kf["delta_count"] > 0
    st.write_objects(os.path.join(w, "objects"))
    assert os.path.exists(os.path.join(w, "objects", "objects.csv"))
    assert "session_01" in st.log() and st.digest() == ltmapper.Store(store_path).digest()
    # The same store step by step: map_init, then Store(read_only=False).integrate.
    p2 = os.path.join(w, "m2.ltmap")
    assert ltmapper.map_init(p2, ltmapper.MapConfig(), truth_aligned, changes)["session"] == 0
    st2 = ltmapper.Store(p2, read_only=False)
    assert st2.integrate(truth_aligned, changes, "session_01")["points"] == steps[1]["points"]
    raises(ltmapper.Error, ltmapper.map_init, p2, ltmapper.MapConfig(), truth_aligned, changes, match="exists")
    raises(ltmapper.Error, st.map_at, "no_such_session", match="no_such_session")
    raises(ltmapper.Error, ltmapper.Store, os.path.join(w, "none.ltmap"), match="none.ltmap")

    # Evaluators: trajectories (dicts of the report JSON) and HD removal on the sim truth.
    tr = ltmapper.load_sim_trajectories(sim_dir(), "")  # drifted session odometry
    assert tr["missing"] == [] and len(tr["sessions"]) == 2
    t = ltmapper.evaluate_trajectories(tr["sessions"])
    assert t["ate"]["trans_m"]["n"] == 20 and math.isfinite(t["ate"]["trans_m"]["rmse"])
    assert ltmapper.load_sim_trajectories(sim_dir(), aligned)["sessions"][0]["est"].shape == (10, 4, 4)
    same = [(s["name"], s["truth"], s["truth"]) for s in tr["sessions"]]
    assert ltmapper.evaluate_trajectories(same)["ate"]["trans_m"]["rmse"] < 1e-9
    hd = ltmapper.evaluate_hd_sim(sim_dir(), "session_00", static, ltmapper.read_kitti_poses(truth_poses(0)),
                                  threads=2)
    assert hd["scans"] == 10 and hd["sa"] > 0.9 and 0.0 <= hd["da"] <= 1.0
    truth = ltmapper.read_ply(os.path.join(sim_dir(), "truth", "session_00", "static_world.ply"))
    h2 = ltmapper.evaluate_hd(truth, static)
    assert h2["static_total"] > 0 and h2["sa"] > 0.5
    # LD: LT-removert ran on the true world poses, so its changes and the sim truth share a frame.
    pred = ltmapper.read_change_clouds(ltmapper.find_pair_dir(changes, "00_01"))
    truth_ld = ltmapper.read_change_clouds(ltmapper.find_pair_dir(os.path.join(sim_dir(), "truth"), "00_01"))
    kept = ltmapper.kept_map_from_changes(static, pred["nd_strong"])
    ld = ltmapper.evaluate_ld(truth_ld, pred, kept_map=kept)
    assert ld["pd"]["truth"] == len(truth_ld["pd_strong"]) + len(truth_ld["pd_weak"]) and ld["weak_nd_kept"]["kept_map_given"]
    raises(ValueError, ltmapper.evaluate_ld, {"pd_strong": pred["pd_strong"]}, pred)
    assert "nd_objects" not in ld
    objs = ltmapper.read_object_change_clouds(ltmapper.find_pair_dir(os.path.join(sim_dir(), "truth"), "00_01"))
    lo = ltmapper.evaluate_ld(truth_ld, pred, truth_objects=objs)
    assert lo["nd_objects"]["truth"] == len(objs["nd_strong"]) + len(objs["nd_weak"])
    assert lo["pd_objects"]["truth"] == len(objs["pd_strong"]) + len(objs["pd_weak"])
    assert lo["pd"]["recall"] == ld["pd"]["recall"] and lo["nd_objects"]["precision"] is None
    assert ltmapper.read_object_change_clouds(changes) is None
    # The multi-session cleanup: the central's map minus the residues of movers its pair found.
    cleaned, note = ltmapper.cleaned_session_map(changes, "session_00")
    residue = ltmapper.read_cloud(os.path.join(ltmapper.find_pair_dir(changes, "00_01"), "nd_residue.pcd"))
    assert len(cleaned) == len(static) - len(residue) and note.startswith(changes)
    raises(ltmapper.Error, ltmapper.evaluate_hd_sim, sim_dir(), "session_09", static,
           ltmapper.read_kitti_poses(truth_poses(0)))



CONFIG_CLASSES = ("SimConfig", "SlamConfig", "RemovertConfig", "MapConfig", "EvalConfig", "RunConfig")


def test_every_config_class():
    """Every bound config: construction, keys / dicts, sections, validate, copy, YAML, errors."""
    for name in CONFIG_CLASSES:
        cls = getattr(ltmapper, name)
        c = cls()
        assert c.validate() is None and c == cls() and str(c) and name in repr(c)
        d = c.to_dict()
        assert list(d) == c.keys() and len(d) > 0
        dotted = [k for k in d if "." in k]
        if dotted:  # a section: attribute access to the dotted keys
            sec = getattr(c, dotted[0].split(".")[0])
            assert isinstance(sec, ltmapper.ConfigSection) and dotted[0].split(".")[1] in dir(sec)
            assert sec.to_dict()[dotted[0].split(".", 1)[1]] == d[dotted[0]] and "section" in repr(sec)
        assert set(dir(c)) >= {k.split(".")[0] for k in d}
        assert c.copy() == c and __import__("copy").deepcopy(c) == c
        raises(ltmapper.Error, c.set, "no_such_key_anywhere=1", match="no_such_key_anywhere")
        raises(ltmapper.Error, cls.from_yaml, os.path.join(work(), "missing_%s.yaml" % name), match="missing_%s" % name)
    r = ltmapper.RunConfig.from_yaml(os.path.join(SOURCE_DIR, "config", "params_run.yaml"))
    assert r.keys() == ltmapper.RunConfig().keys()
    # validate() applies the cross-field rules a stage would (here: a range the field allows but
    # the config as a whole does not), with the C++ message.
    m = ltmapper.MapConfig()
    errors = []
    for k, v in m.to_dict().items():
        if isinstance(v, float) and v > 0:
            try:
                m.set(k, 0.0)
            except ltmapper.Error as e:
                errors.append(str(e))
                continue
            try:
                m.validate()
            except ltmapper.Error as e:
                errors.append(str(e))
            m = ltmapper.MapConfig()
    assert errors and all(msg for msg in errors)


def test_session_objects_and_sensor_fields():
    s = ltmapper.load_session(session_dir(0))
    assert isinstance(s, ltmapper.Session) and isinstance(s.keyframes[0], ltmapper.Keyframe)
    k = s.keyframes[0]
    assert k.cloud_path.endswith(".pcd") and os.path.exists(k.cloud_path) and "Keyframe" in repr(k)
    assert isinstance(s.loops, list) and all(l["T_from_to"].shape == (4, 4) for l in s.loops)
    assert "Session" in repr(s)
    v = ltmapper.sensor_preset("vlp16")
    assert isinstance(v, ltmapper.SensorModel)
    assert len(v.elevations_deg) == v.beams == 16 and v.ring_based in (True, False)
    assert v.azimuth_step_deg > 0 and v.grid_deg >= 0 and v.fov_up_deg > v.fov_down_deg and v.spread_deg >= 0
    assert v.spacing_at(0.0) > 0 and v.max_spacing() >= v.median_spacing() > 0
    assert "vlp16" in repr(v) or v.describe() in repr(v)
    raises(ltmapper.Error, ltmapper.sensor_from_table, [])
    raises(ltmapper.Error, ltmapper.estimate_sensor, [])


def test_kitti_layout_and_pose_files():
    """load_kitti_session, read_transform, read_poses (KITTI and TUM) on files written here."""
    d = os.path.join(work(), "kitti")
    os.makedirs(os.path.join(d, "velodyne"), exist_ok=True)
    s = ltmapper.load_session(session_dir(0))
    poses = s.poses[:3]
    for i in range(3):
        ltmapper.write_kitti_bin(os.path.join(d, "velodyne", "%06d.bin" % i), s.scan(i))
    ltmapper.write_kitti_poses(os.path.join(d, "poses.txt"), poses)
    k = ltmapper.load_kitti_session(d, os.path.join(d, "poses.txt"))
    assert len(k) == 3 and np.allclose(k.poses, poses, atol=1e-6)
    np.testing.assert_array_equal(k.scan(1), s.scan(1))
    tr = np.eye(4)
    tr[:3, 3] = (0.1, -0.2, 0.3)
    with open(os.path.join(d, "calib_tr.txt"), "w") as f:
        f.write(" ".join("%.9f" % v for v in tr[:3].reshape(-1)) + "\n")
    np.testing.assert_allclose(ltmapper.read_transform(os.path.join(d, "calib_tr.txt")), tr, atol=1e-9)
    kt = ltmapper.load_kitti_session(d, os.path.join(d, "poses.txt"), T_cam_velo=tr)
    assert len(kt) == 3 and not np.allclose(kt.poses[1], k.poses[1])  # camera poses moved into the LiDAR frame
    np.testing.assert_allclose(ltmapper.read_poses(os.path.join(d, "poses.txt")), poses, atol=1e-6)
    with open(os.path.join(d, "poses_tum.txt"), "w") as f:
        f.write("0 1 2 3 0 0 0 1\n1 4 5 6 0 0 0 1\n")
    tum = ltmapper.read_poses(os.path.join(d, "poses_tum.txt"))
    assert tum.shape == (2, 4, 4) and tuple(tum[1, :3, 3]) == (4, 5, 6)
    raises(ltmapper.Error, ltmapper.load_kitti_session, d, os.path.join(d, "none.txt"), match="none.txt")
    raises(ValueError, ltmapper.load_kitti_session, d, os.path.join(d, "poses.txt"), T_cam_velo=np.eye(3))
    with open(os.path.join(d, "bad_tr.txt"), "w") as f:
        f.write("1 2 3\n")
    raises(ltmapper.Error, ltmapper.read_transform, os.path.join(d, "bad_tr.txt"), match="bad_tr.txt")


def test_bad_paths_raise_the_cpp_message():
    """Every entry point that reads a path: ltmapper.Error naming the missing file or folder."""
    w = work()
    gone = os.path.join(w, "gone_%s")
    cfg = {"slam": ltmapper.SlamConfig(), "rem": ltmapper.RemovertConfig(), "map": ltmapper.MapConfig()}
    calls = [
        ("read_cloud", lambda p: ltmapper.read_cloud(p + ".pcd")),
        ("read_ply", lambda p: ltmapper.read_ply(p + ".ply")),
        ("read_kitti_poses", lambda p: ltmapper.read_kitti_poses(p + ".txt")),
        ("read_poses", lambda p: ltmapper.read_poses(p + ".txt")),
        ("read_transform", lambda p: ltmapper.read_transform(p + ".txt")),
        ("load_session", lambda p: ltmapper.load_session(p)),
        ("load_kitti_session", lambda p: ltmapper.load_kitti_session(p, p + "/poses.txt")),
        ("inspect_session", lambda p: ltmapper.inspect_session(p)),
        ("read_change_clouds", lambda p: ltmapper.read_change_clouds(p)),
        ("find_pair_dir", lambda p: ltmapper.find_pair_dir(p, "00_01")),
        ("sim_session_names", lambda p: ltmapper.sim_session_names(p)),
        ("load_sim_trajectories", lambda p: ltmapper.load_sim_trajectories(p)),
        ("truth_to_estimate_frame", lambda p: ltmapper.truth_to_estimate_frame(p)),
        ("evaluate_hd_sim", lambda p: ltmapper.evaluate_hd_sim(p, "session_00", np.zeros((1, 4), np.float32), np.eye(4)[None])),
        ("aligned_sessions", lambda p: ltmapper.aligned_sessions(p)),
        ("run_slam", lambda p: ltmapper.run_slam(cfg["slam"], p, [session_dir(1)], os.path.join(w, "out_slam"))),
        ("run_removert", lambda p: ltmapper.run_removert(cfg["rem"], [p], [p + ".txt"], os.path.join(w, "out_rem"))),
        ("run_pipeline", lambda p: ltmapper.run_pipeline(ltmapper.RunConfig(), [session_dir(0), p], os.path.join(w, "out_run"))),
        ("map_init", lambda p: ltmapper.map_init(os.path.join(w, "x.ltmap"), cfg["map"], p, p)),
        ("map_integrate", lambda p: ltmapper.map_integrate(os.path.join(w, "y.ltmap"), cfg["map"], p, p)),
        ("Store", lambda p: ltmapper.Store(p + ".ltmap")),
        ("write_pcd", lambda p: ltmapper.write_pcd(open(p, "w").close() or p + "/x.pcd", np.zeros((1, 4), np.float32))),
    ]
    for name, call in calls:
        p = gone % name
        try:
            call(p)
        except ltmapper.Error as e:
            assert ("gone_%s" % name) in str(e), "%s: %r does not name the path" % (name, str(e))
            continue
        raise AssertionError("%s did not raise ltmapper.Error on a missing path" % name)


def test_truth_frame_objects_and_labelled_clouds():
    w = work()
    T = ltmapper.truth_to_estimate_frame(sim_dir())
    assert T.shape == (4, 4) and np.allclose(T[3], (0, 0, 0, 1))
    csv = os.path.join(w, "objects_classes.csv")
    with open(csv, "w") as f:
        f.write("id,class\n3,car\n7,bin\n")
    try:
        classes = ltmapper.read_object_classes(csv)
        assert isinstance(classes, dict)
    except ltmapper.Error as e:  # a different header: the message names the file
        assert "objects_classes.csv" in str(e)
    truth_csv = os.path.join(sim_dir(), "truth", "objects.csv")
    classes = ltmapper.read_object_classes(truth_csv)
    assert ltmapper.read_object_classes(os.path.join(w, "no_objects.csv")) == {}  # optional file: none
    assert classes and all(isinstance(k, int) and isinstance(v, str) for k, v in classes.items())
    lab = {"points": np.arange(40, dtype=np.float32).reshape(10, 4), "cls": np.full(10, 5, np.uint8),
           "session": np.ones(10, np.uint16), "object": np.full(10, -1, np.int32)}
    for ext in ("ply", "pcd"):
        p = os.path.join(w, "labelled." + ext)
        ltmapper.write_labelled_cloud(p, lab)
        assert os.path.getsize(p) > 0
    np.testing.assert_array_equal(ltmapper.read_ply(os.path.join(w, "labelled.ply"))["cls"], lab["cls"])
    raises(ValueError, ltmapper.write_labelled_cloud, os.path.join(w, "bad.ply"), {"points": lab["points"], "cls": lab["cls"][:3]})


def test_store_threads_order_and_pipeline():
    """Store.set_threads / session_order on the store of test_stages_store_eval; run_pipeline."""
    w = work()
    st = ltmapper.Store(os.path.join(w, "m.ltmap"))
    st.set_threads(1)
    one = st.map_at(st.latest_session)["points"]
    st.set_threads(2)
    np.testing.assert_array_equal(st.map_at(st.latest_session)["points"], one)  # same for any thread count
    assert st.session_order(st.session_names()[0]) == 0 and st.session_order(st.session_names()[-1]) == st.latest_session
    raises(ltmapper.Error, st.session_order, "no_such_session", match="no_such_session")
    raises(ltmapper.Error, st.map_at, 99)
    raises(ValueError, st.map_at, 0, voxel=-1.0)
    raises(ValueError, st.map_at, 0, box=((0, 0), (1, 1)))
    raises(ltmapper.Error, st.integrate, w, w, "session_01")  # opened read-only
    # `ltmapper run` on the tiny 10-keyframe routes: LT-SLAM aligns the query (its loop verification
    # judges surfaces, not point distances, since the sparse tiny scans failed the old RMS bound),
    # then LT-removert and LT-map; the report lists the three stages and the outputs exist.
    out = os.path.join(w, "run")
    r = ltmapper.run_pipeline(ltmapper.RunConfig(), [session_dir(0), session_dir(1)], out, threads=2)
    assert r["sessions"] == ["session_00", "session_01"] and r["aligned"] == r["sessions"] and not r["not_aligned"]
    assert [s["stage"] for s in r["stages"]] == ["slam", "removert", "map"] and r["map_points_live"] > 0
    assert os.path.exists(os.path.join(out, "map.ltmap")) and os.path.exists(os.path.join(out, "live.pcd"))
    raises(ltmapper.Error, ltmapper.run_pipeline, ltmapper.RunConfig({"from_stage": "map"}), [session_dir(0)],
           os.path.join(w, "run_nothing"))
    # `run --poses`: the sessions placed by the true poses, the query's rotation error measured.
    given = os.path.join(w, "run_given")
    r = ltmapper.run_pipeline(ltmapper.RunConfig(), [session_dir(0), session_dir(1)], given, threads=2,
                              poses=[truth_poses(0), truth_poses(1)])
    assert r["aligned"] == ["session_00", "session_01"] and r["map_points_live"] > 0
    manifest = open(os.path.join(given, "aligned", "manifest.yaml")).read()
    assert "rotation_sigma_deg" in manifest, manifest
    placed = np.loadtxt(os.path.join(given, "aligned", "session_01", "poses_world.txt"))
    np.testing.assert_allclose(placed, np.loadtxt(truth_poses(1)), atol=1e-6)
    raises(ltmapper.Error, ltmapper.run_pipeline, ltmapper.RunConfig(), [session_dir(0), session_dir(1)], given,
           poses=[truth_poses(0)], match="2 sessions but 1 pose files")


def test_trace_object():
    """bench/trace_object.py on the true-poses run of test_store_threads_order_and_pipeline: each
    truth object's change points, in the run's frame (the truth's, as the poses are true), with an
    LD class each, and a clear error for an object that is no change."""
    sys.path.insert(0, os.path.join(SOURCE_DIR, "bench"))
    import trace_object
    w = work()
    given = os.path.join(w, "run_given")
    truth = ltmapper.read_ply(os.path.join(sim_dir(), "truth", "pair_00_01", "objects_changes.ply"))
    ids = sorted(set(int(o) for o in truth["object"]))
    assert ids, "the tiny scenario's pair changes no object"
    for obj in ids:
        t = trace_object.trace(sim_dir(), given, obj, eval_json=None)
        mine = truth["points"][truth["object"] == obj, :3]
        assert t["pair"] == "00_01" and t["change_points"] == len(mine)
        np.testing.assert_allclose(t["box_world"]["min"], mine.min(0), atol=2e-3)
        np.testing.assert_allclose(t["box_world"]["max"], mine.max(0), atol=2e-3)
        cells = [(tc, lc, n) for tc, row in t["ld"]["truth_x_ld"].items() for lc, n in row.items()]
        assert sum(n for _, _, n in cells) == len(mine)
        assert all(tc in trace_object.CHANGE_CLASSES for tc, _, _ in cells)
        assert all(lc in trace_object.LD_CLOUDS + ("none",) for _, lc, _ in cells)
        assert [s["session"] for s in t["sessions"]] == ["00", "01"] and all(s["aligned"] for s in t["sessions"])
        assert all(o["reason"] for o in t["objects"])
        assert t["beams"] is None
    # --beams: the judging session's scans agree with the beam truth. The truth calls a point strong
    # ND where a query ray passed within the tolerance and met nothing or ended beyond it, weak where
    # none did; the verdicts read back from the scans (a sky or beyond verdict) must say the same
    # for nearly every point.
    agree = total = 0
    for obj in ids:
        t = trace_object.trace(sim_dir(), given, obj, eval_json=None, with_beams=True)
        counts = [(k.split()[0], v, n) for k, row in t["beams"].items() for v, n in row.items()]
        assert sum(n for _, _, n in counts) == t["change_points"]
        assert all(v in trace_object.BEAM_VERDICTS for _, v, _ in counts)
        for tc, v, n in counts:
            if tc in ("nd_strong", "nd_weak"):
                passed = v in trace_object.SEEN_THROUGH
                agree += n if passed == (tc == "nd_strong") else 0
                total += n
    print("trace_object --beams: %d of %d ND points agree with the beam truth" % (agree, total))
    assert total > 0 and agree >= 0.9 * total, (agree, total)
    raises(trace_object.TraceError, trace_object.trace, sim_dir(), given, max(ids) + 1000,
           match=os.path.join(sim_dir(), "truth"))
    raises(trace_object.TraceError, trace_object.trace, sim_dir(), os.path.join(w, "no_run"), ids[0],
           match="no_run")

if __name__ == "__main__":
    t0 = time.time()
    tests = [(n, f) for n, f in sorted(globals().items(), key=lambda kv: kv[0]) if n.startswith("test_")]
    tests.sort(key=lambda nf: nf[1].__code__.co_firstlineno)
    failed = 0
    for name, fn in tests:
        t = time.time()
        try:
            fn()
            print("ok   %-28s %.2f s" % (name, time.time() - t), flush=True)
        except Exception:
            failed += 1
            import traceback
            traceback.print_exc()
            print("FAIL %s" % name, flush=True)
    print("%d passed, %d failed in %.1f s" % (len(tests) - failed, failed, time.time() - t0))
    sys.exit(1 if failed else 0)
