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

    # evo itself, as `evo_ape tum estimates_truth.txt estimates.txt` reads them: no alignment
    from evo.core import metrics
    from evo.tools import file_interface

    tum = out / "export" / "tum" / recall
    true = file_interface.read_tum_trajectory_file(str(tum / "estimates_truth.txt"))
    est = file_interface.read_tum_trajectory_file(str(tum / "estimates.txt"))
    assert np.array_equal(est.timestamps, locs["time_s"][ok])
    assert np.array_equal(est.timestamps, true.timestamps)
    for relation, stored, atol in (
        (metrics.PoseRelation.translation_part, "position_error_3d_m", 1e-6),
        (metrics.PoseRelation.rotation_angle_deg, "rotation_error_deg", 1e-4),
    ):
        ape = metrics.APE(relation)
        ape.process_data((true, est))
        assert np.allclose(ape.error, locs[stored][ok], atol=atol), stored
    truth_rows = len(read_episode_table(out, recall, "trajectory")["time_s"])
    kitti = np.loadtxt(out / "export" / "kitti" / recall / "ekf.txt")
    assert kitti.shape == (truth_rows, 12)
    baseline = out / "export" / "tum" / rows["baseline"].key
    assert sorted(p.name for p in baseline.iterdir()) == ["ekf.txt", "truth.txt"]

    hloc = out / "export" / "hloc" / recall

    def cam_poses(name):
        """As hloc's evaluation reads a results file: every line a name and seven numbers."""
        poses = {}
        for line in (hloc / name).read_text().splitlines():
            name, *data = line.split()
            q, t = np.split(np.array(data, float), [4])
            poses[name] = make_pose(rotation_from_quaternion(*q[1:], q[0]), t)
        return poses

    results, truth = cam_poses("results.txt"), cam_poses("ground_truth.txt")
    assert len(results) == ok.sum() and len(truth) == len(ok)
    queries = (hloc / "queries_with_intrinsics.txt").read_text().splitlines()
    assert len(queries) == len(ok) and queries[0].split()[1:4] == ["PINHOLE", "320", "240"]
    for k, name in zip(np.flatnonzero(ok), results, strict=True):  # cam_from_world, COLMAP's
        _, rotation_deg = pose_error(np.linalg.inv(truth[name]), np.linalg.inv(results[name]))
        assert rotation_deg == pytest.approx(locs["rotation_error_deg"][k], abs=1e-4)
    [model] = (out / "export" / "colmap").iterdir()
    assert pycolmap.Reconstruction(model).num_reg_images() > 10
