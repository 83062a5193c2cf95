"""Learned methods run offline: weights come from installed packages, nothing is downloaded."""

import socket

import numpy as np
import pytest

from tests.conftest import CAMERA, query_pose

torch = pytest.importorskip("torch")


@pytest.fixture
def offline(monkeypatch, tmp_path):
    """No network for this process, and every hub/cache directory pointed at an empty folder."""
    for var in ("TORCH_HOME", "HF_HOME", "XDG_CACHE_HOME"):
        monkeypatch.setenv(var, str(tmp_path / var.lower()))
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")

    def refuse(*args, **kwargs):
        raise OSError("network disabled in this test")

    monkeypatch.setattr(socket.socket, "connect", refuse)
    monkeypatch.setattr(socket, "create_connection", refuse)
    monkeypatch.setattr(torch.hub, "get_dir", lambda: str(tmp_path / "torch_hub"))
    yield tmp_path
    written = [p for p in tmp_path.rglob("*") if p.is_file()]
    assert not written, f"weights cache written: {written}"


def test_aliked_lightglue_and_effnet_localize_offline(
    offline, gallery, small_town, stretch, tmp_path_factory
):
    from vlocbench.bench.visual import camera_model
    from vlocbench.loc.gallery import GalleryWriter
    from vlocbench.loc.localizer import MapLocalizer
    from vlocbench.loc.mapping import MappingConfig, build_map
    from vlocbench.loc.registry import method_conf
    from vlocbench.sim import Simulator

    # the first 32 m only (learned methods are slow on a CPU)
    root = tmp_path_factory.mktemp("learned")
    writer = GalleryWriter(root / "gallery")
    for name in gallery.names[:16]:
        im = gallery.images[gallery.index_of(name)]
        writer.add(
            name, gallery.load_image(name), im.camera, gallery.cameras[im.camera], im.world_from_cam
        )
    small = writer.close()
    out = root / "aliked"
    report = build_map(small, method_conf("aliked-lightglue"), out, MappingConfig(num_pairs=3))
    assert report.points > 300
    localizer = MapLocalizer(out)
    sim = Simulator(small_town)
    sim.teleport(*query_pose(stretch, 6))
    frame = sim.render([CAMERA])[0]
    sim.close()
    result = localizer.localize(frame.image, camera_model(CAMERA))
    assert result.success, result.reason
    assert np.linalg.norm(result.world_from_cam[:3, 3] - frame.world_from_cam[:3, 3]) < 0.25


def test_disk_features_and_lightglue_match_offline(offline, gallery):
    from vlocbench.loc.registry import build_features, build_matcher

    a, b = (gallery.load_image(n) for n in gallery.names[10:12])
    disk = build_features("disk")
    fa, fb = disk.extract(a), disk.extract(b)
    assert len(fa) > 200 and fa.descriptors.shape[1] == 128
    matches = build_matcher("lightglue-disk").match(fa, fb)
    assert len(matches) > 50
    assert len(np.unique(matches[:, 1])) == len(matches)  # one-to-one


def test_xfeat_and_lighterglue_match_offline_and_agree_with_the_true_geometry(offline, gallery):
    from vlocbench.loc.registry import build_features, build_matcher

    i, j = 10, 11  # gallery places 2 m apart
    a, b = (gallery.load_image(gallery.names[k]) for k in (i, j))
    xfeat = build_features("xfeat")
    fa, fb = xfeat.extract(a), xfeat.extract(b)
    assert len(fa) > 200 and fa.descriptors.shape[1] == 64
    matches = build_matcher("lighterglue-xfeat").match(fa, fb)
    assert len(matches) > 50
    assert len(np.unique(matches[:, 1])) == len(matches)  # one-to-one
    # the fundamental matrix of the two known camera poses
    world_from_a, world_from_b = (gallery.images[k].world_from_cam for k in (i, j))
    b_from_a = np.linalg.inv(world_from_b) @ world_from_a
    t = b_from_a[:3, 3]
    essential = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]]) @ b_from_a[:3, :3]
    k_inv = np.linalg.inv(CAMERA.intrinsics.K)
    fundamental = k_inv.T @ essential @ k_inv
    xa = np.c_[fa.keypoints[matches[:, 0]], np.ones(len(matches))]
    xb = np.c_[fb.keypoints[matches[:, 1]], np.ones(len(matches))]
    lines = xa @ fundamental.T  # epipolar lines in b
    distance_px = np.abs(np.sum(lines * xb, axis=1)) / np.hypot(lines[:, 0], lines[:, 1])
    assert np.median(distance_px) < 1.5 and np.mean(distance_px < 3.0) > 0.8
