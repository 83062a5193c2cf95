"""Exports read back as their tools read them (evo's TUM, hloc's results, COLMAP's model)."""

import numpy as np
import pycolmap
import pytest

from vlocbench.bench.store import ResultStore


def test_a_run_exports_for_evo_hloc_and_colmap(tiny, capsys):
    """TUM and hloc files of the real run: the errors between their poses are the store's own."""

    from vlocbench.bench.store import read_episode_table
    from vlocbench.cli import main
    from vlocbench.geometry import make_pose, pose_error, rotation_from_quaternion

    root, _ = tiny
    out = root / "out"
    for fmt in ("tum", "kitti", "hloc", "colmap"):
        assert main(["export", str(out), "--format", fmt]) == 0
    assert "files to" in capsys.readouterr().out
    assert main(["export", str(out), "--format", "csv"]) == 1
    assert "unknown format 'csv'; valid: colmap, hloc, kitti, tum" in capsys.readouterr().err
    with ResultStore(out, "tiny") as store:
        rows = {r.kind: r for r in store.rows() if r.kind != "failure"}
    recall = rows["recall"].key
    locs = read_episode_table(out, recall, "localizations")
    ok = locs["success"].astype(bool)

    def tum(path):
        a = np.loadtxt(path, ndmin=2)
        return a[:, 0], [make_pose(rotation_from_quaternion(*r[4:8]), r[1:4]) for r in a]

    t_est, est = tum(out / "export" / "tum" / recall / "estimates.txt")
    t_true, true = tum(out / "export" / "tum" / recall / "estimates_truth.txt")
    assert np.array_equal(t_est, locs["time_s"][ok]) and np.array_equal(t_est, t_true)
    errors = np.array([pose_error(a, b) for a, b in zip(true, est, strict=True)])
    assert np.allclose(errors[:, 0], locs["position_error_3d_m"][ok], atol=1e-6)
    assert np.allclose(errors[:, 1], locs["rotation_error_deg"][ok], atol=1e-4)
    truth_rows = len(read_episode_table(out, recall, "trajectory")["time_s"])
    kitti = np.loadtxt(out / "export" / "kitti" / recall / "ekf.txt")
    assert kitti.shape == (truth_rows, 12)
    baseline = out / "export" / "tum" / rows["baseline"].key
    assert sorted(p.name for p in baseline.iterdir()) == ["ekf.txt", "truth.txt"]

    hloc = out / "export" / "hloc" / recall

    def cam_poses(name):
        lines = [x.split() for x in (hloc / name).read_text().splitlines() if x[0] != "#"]
        return {x[0]: make_pose(rotation_from_quaternion(*map(float, (*x[2:5], x[1]))),
                                np.array(x[5:8], float)) for x in lines}  # fmt: skip

    results, truth = cam_poses("results.txt"), cam_poses("ground_truth.txt")
    assert len(results) == ok.sum() and len(truth) == len(ok)
    queries = (hloc / "queries_with_intrinsics.txt").read_text().splitlines()
    assert len(queries) == len(ok) and queries[0].split()[1:4] == ["PINHOLE", "320", "240"]
    for k, name in zip(np.flatnonzero(ok), results, strict=True):  # cam_from_world, COLMAP's
        _, rotation_deg = pose_error(np.linalg.inv(truth[name]), np.linalg.inv(results[name]))
        assert rotation_deg == pytest.approx(locs["rotation_error_deg"][k], abs=1e-4)
    [model] = (out / "export" / "colmap").iterdir()
    assert pycolmap.Reconstruction(model).num_reg_images() > 10
