"""Learned methods run offline: weights come from installed packages, nothing is downloaded."""

import socket

import numpy as np
import pytest

from tests.conftest import CAMERA, last_line_in_a_process, query_pose

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
    from vlocbench.loc.localizer import MapLocalizer
    from vlocbench.loc.mapping import MappingConfig, build_map
    from vlocbench.loc.registry import method_conf
    from vlocbench.sim import Simulator

    # the first 32 m only (learned methods are slow on a CPU)
    root = tmp_path_factory.mktemp("learned")
    small = gallery.head(16, root / "gallery")
    out = root / "aliked"
    # the "-gem" preset: EfficientNet's weights load offline too
    conf = method_conf("aliked-lightglue-gem")
    report = build_map(small, conf, out, MappingConfig(num_pairs=3))
    assert report.points > 300
    localizer = MapLocalizer(out)
    with Simulator(small_town) as sim:
        sim.teleport(*query_pose(stretch, 6))
        frame = sim.render([CAMERA])[0]
    result = localizer.localize(frame.image, camera_model(CAMERA))
    assert result.success, result.reason
    assert np.linalg.norm(result.world_from_cam[:3, 3] - frame.world_from_cam[:3, 3]) < 0.25


def _match_two_gallery_images(gallery, features, matcher, i=10, j=11):
    """Features of gallery images i and j (2 m apart) and their matches, checked one-to-one."""
    from vlocbench.loc.registry import build_features, build_matcher

    a, b = (gallery.load_image(gallery.names[k]) for k in (i, j))
    extractor = build_features(features)
    fa, fb = extractor.extract(a), extractor.extract(b)
    matches = build_matcher(matcher).match(fa, fb)
    assert len(np.unique(matches[:, 1])) == len(matches)  # one-to-one
    return fa, fb, matches


def test_lightglue_for_features_without_weights_lists_the_valid_ones():
    from vlocbench.errors import ConfigError, UnknownNameError
    from vlocbench.loc.learned import LightGlueMatcher

    with pytest.raises(UnknownNameError, match="valid: aliked, disk, xfeat"):
        LightGlueMatcher(features="sift")
    with pytest.raises(ConfigError, match=r"matcher\.batch_size: must be >= 1"):
        LightGlueMatcher(features="xfeat", batch_size=0)


def test_disk_features_and_lightglue_match_offline(offline, gallery):
    fa, _, matches = _match_two_gallery_images(gallery, "disk", "lightglue-disk")
    assert len(fa) > 200 and fa.descriptors.shape[1] == 128
    assert len(matches) > 50


def test_xfeat_and_lighterglue_match_offline_and_agree_with_the_true_geometry(offline, gallery):
    from vlocbench.bench.visual import camera_model
    from vlocbench.loc.mapping import fundamental_from_poses

    i, j = 10, 11
    fa, fb, matches = _match_two_gallery_images(gallery, "xfeat", "lighterglue-xfeat", i, j)
    assert len(fa) > 200 and fa.descriptors.shape[1] == 64
    assert len(matches) > 50
    # the fundamental matrix of the two known camera poses
    world_from_a, world_from_b = (gallery.images[k].world_from_cam for k in (i, j))
    cam = camera_model(CAMERA)
    fundamental = fundamental_from_poses(cam, world_from_a, cam, world_from_b)
    xa = np.c_[fa.keypoints[matches[:, 0]], np.ones(len(matches))]
    xb = np.c_[fb.keypoints[matches[:, 1]], np.ones(len(matches))]
    lines = xa @ fundamental.T  # epipolar lines in b
    distance_px = np.abs(np.sum(lines * xb, axis=1)) / np.hypot(lines[:, 0], lines[:, 1])
    assert np.median(distance_px) < 1.5 and np.mean(distance_px < 3.0) > 0.8


def test_xfeat_keypoint_budgets_are_presets(offline, gallery):
    """``xfeat`` keeps the strongest 1024 keypoints, ``xfeat-4096`` (the paper's SuperPoint's
    budget) the strongest 4096: the same detections, more of them."""
    from vlocbench.loc.registry import build_features, method_conf

    assert method_conf("xfeat-lighterglue-4096").features == "xfeat-4096"
    small = gallery.load_image(gallery.names[10])
    image = small.repeat(3, axis=0).repeat(3, axis=1)  # enlarged: more than 1024 detections
    few, many = (build_features(name).extract(image) for name in ("xfeat", "xfeat-4096"))
    assert len(few) == 1024 and 1024 < len(many) <= 4096
    assert np.isin(few.keypoints.view("f4,f4"), many.keypoints.view("f4,f4")).all()


def test_thresholded_aliked_finds_fewer_keypoints_the_darker_the_image(small_town, stretch):
    """``aliked`` keeps its strongest 1024 keypoints whatever the light; ``aliked-threshold``
    (ALIKED's own mode) those scoring above 0.2, so a night image gives fewer, as SuperPoint's
    fixed threshold does: keypoints of the top-k mode's, fewer of them."""
    from vlocbench.loc.registry import build_features, method_conf
    from vlocbench.sim import Conditions, Illumination, Simulator

    assert method_conf("aliked-lightglue-threshold").features == "aliked-threshold"
    top_k, threshold = build_features("aliked"), build_features("aliked-threshold")
    counts = {}
    with Simulator(small_town) as sim:
        sim.teleport(*query_pose(stretch, 6))
        for k in (0.0, 10.0):
            sim.set_conditions(Conditions(illumination=Illumination(k=k)))
            image = sim.render([CAMERA])[0].image
            ranked, kept = top_k.extract(image), threshold.extract(image)
            assert np.isin(kept.keypoints.view("f4,f4"), ranked.keypoints.view("f4,f4")).all()
            counts[k] = (len(ranked), len(kept))
    # measured: 1024 and 822 keypoints by rank, 95 and 30 above the threshold
    (day_ranked, day_kept), (night_ranked, night_kept) = counts[0.0], counts[10.0]
    assert day_ranked == 1024 and night_ranked > 0.75 * day_ranked
    assert night_kept < 0.5 * day_kept


def test_batched_lighterglue_gives_each_pair_its_own_matches(offline, gallery):
    """Pairs grouped by keypoint counts come back in order, each as matched alone: one pass per
    batch where LightGlue prunes no points (as on a GPU), one pair at a time where it does."""
    from vlocbench.loc.features import Features
    from vlocbench.loc.learned import LightGlueMatcher
    from vlocbench.loc.matchers import match_pairs
    from vlocbench.loc.registry import build_features

    extractor = build_features("xfeat")
    f = [extractor.extract(gallery.load_image(gallery.names[k])) for k in (10, 11, 12, 13)]
    cut = f[2].subset(np.arange(300))  # another keypoint count: its own batch
    pairs = [(f[0], f[1]), (f[1], f[2]), (cut, f[3]), (f[2], f[3]), (f[0], Features.empty(64))]
    matcher = LightGlueMatcher(features="xfeat", batch_size=2)
    assert not matcher._one_pass(1024)  # the CPU prunes points: pairs one at a time
    alone = [matcher.match(a, b) for a, b in pairs]
    assert all(
        np.array_equal(x, y) for x, y in zip(alone, match_pairs(matcher, pairs), strict=True)
    )
    # without pruning and early stopping a batch is one pass and each pair's result its own
    matcher.net.conf.width_confidence = matcher.net.conf.depth_confidence = -1
    assert matcher._one_pass(1024)
    alone = [matcher.match(a, b) for a, b in pairs]
    batched = match_pairs(matcher, pairs)
    assert min(len(m) for m in alone[:4]) > 50 and batched[4].shape == (0, 2)
    for x, y in zip(alone, batched, strict=True):
        same = {tuple(r) for r in x} & {tuple(r) for r in y}
        assert len(same) >= 0.98 * max(len(x), len(y))  # floating point's order of sums only


def test_learned_features_do_not_depend_on_the_callers_threads(offline, gallery):
    """A map built alone in the driver (every core) and one built in a pool worker (one thread)
    must be the same map: the float sums of a forward pass round by their split over threads."""
    from vlocbench.loc.registry import build_features, build_retrieval

    image = gallery.load_image(gallery.names[10])
    extractor, retrieval = build_features("xfeat"), build_retrieval("effnet-gem")
    before = torch.get_num_threads()
    try:
        runs = []
        for threads in (1, 2):
            torch.set_num_threads(threads)
            f = extractor.extract(image)
            runs.append((f.descriptors, retrieval.describe(image, f)))
            assert torch.get_num_threads() == threads  # the caller's setting is kept
    finally:
        torch.set_num_threads(before)
    for one, two in zip(*runs, strict=True):
        assert np.array_equal(one, two)


def test_image_normalized_retrieval_describes_a_darker_image_as_the_same_place(offline, gallery):
    """input_norm "image" divides out a uniform darkening (the night of a camera past its
    exposure range); ImageNet's fixed statistics do not. An unknown value lists the valid ones."""
    from vlocbench.errors import UnknownNameError
    from vlocbench.loc.learned import EfficientNetGem
    from vlocbench.loc.registry import build_retrieval

    day = gallery.load_image(gallery.names[10])
    night = np.round(day.astype(np.float64) / 16.0).astype(np.uint8)  # 4 stops darker, quantized
    rank = {}  # of the dark image's own place among the gallery's, as a retrieval query
    for name in ("effnet-gem", "effnet-gem-norm"):
        retrieval = build_retrieval(name)
        query = retrieval.describe(night, None)
        similarity = np.array(
            [float(query @ retrieval.describe(gallery.load_image(n), None)) for n in gallery.names]
        )
        rank[name] = int(np.sum(similarity > similarity[10]))
    # measured on scene 7's small town: 0 (first of 30) and 10
    assert rank["effnet-gem-norm"] == 0 and rank["effnet-gem"] > 0
    with pytest.raises(UnknownNameError, match="valid: image, imagenet"):
        EfficientNetGem(input_norm="contrast")


def test_the_learned_method_retrieves_a_darker_image_by_its_own_descriptors(offline, gallery):
    """xfeat-lighterglue retrieves with VLAD over XFeat's descriptors, its vocabulary from the
    gallery: a uniformly darker image of a place (which ImageNet's EfficientNet-GeM places
    elsewhere, the test above) is its own place first."""
    from vlocbench.loc.registry import build_features, build_retrieval, method_conf

    conf = method_conf("xfeat-lighterglue")
    extractor, retrieval = build_features(conf.features), build_retrieval(conf.retrieval)
    assert retrieval is not None and retrieval.name == "vlad"
    images = [gallery.load_image(n) for n in gallery.names]
    features = [extractor.extract(image) for image in images]
    retrieval.fit(features)
    described = np.stack([retrieval.describe(i, f) for i, f in zip(images, features)])
    night = np.round(images[10].astype(np.float64) / 16.0).astype(np.uint8)  # 4 stops darker
    query = retrieval.describe(night, extractor.extract(night))
    similarity = described @ query
    assert int(np.sum(similarity > similarity[10])) == 0


def test_the_device_is_auto_cpu_or_cuda(monkeypatch):
    from vlocbench.errors import ConfigError, UnknownNameError
    from vlocbench.loc.learned import EfficientNetGem, resolve_device

    monkeypatch.delenv("VLOCBENCH_DEVICE", raising=False)
    expected = "cuda" if torch.cuda.is_available() else "cpu"
    assert resolve_device("auto") == expected and resolve_device("cpu") == "cpu"
    monkeypatch.setenv("VLOCBENCH_DEVICE", "cpu")
    assert resolve_device() == "cpu"
    assert EfficientNetGem().device == "cpu"
    with pytest.raises(UnknownNameError, match="valid: auto, cpu, cuda, cuda:N"):
        resolve_device("tpu")
    if not torch.cuda.is_available():
        with pytest.raises(ConfigError, match="sees no GPU"):
            resolve_device("cuda")


def test_the_compute_fingerprint_follows_the_cpus_kernels_not_the_process():
    """A forward pass's rounding depends on the vector kernels PyTorch picks for the CPU: the
    digest is the same in every process of a machine, another where other kernels run."""
    from vlocbench.loc.learned import compute_fingerprint

    code = (
        "from vlocbench.loc.learned import compute_fingerprint; print(compute_fingerprint('cpu'))"
    )

    here = compute_fingerprint("cpu")
    assert len(here) == 16 and last_line_in_a_process(code, OMP_NUM_THREADS="1") == here
    capability = torch.backends.cpu.get_cpu_capability()
    if capability == "DEFAULT":
        pytest.skip("this CPU runs PyTorch's plain kernels: no other to compare with")
    assert last_line_in_a_process(code, ATEN_CPU_CAPABILITY="default") != here


def test_a_learned_maps_features_and_matches_made_in_a_pool_are_the_drivers(
    offline, gallery, tmp_path_factory, monkeypatch
):
    """A single map build spreads its images' extraction and its LighterGlue pairs over pool
    processes (``vlocbench build-map --workers 2`` here, a run's workers in ``prepare_maps``):
    chunk by chunk, each image and pair on one thread, so the features, the matches and the map
    are those of the build in one process."""
    import h5py

    from vlocbench.cli import main
    from vlocbench.loc import mapping
    from vlocbench.loc.registry import method_conf

    tmp_path = tmp_path_factory.mktemp("pooled")  # the offline check owns tmp_path
    small = gallery.head(10, tmp_path / "gallery")
    assert small.names == gallery.names[:10] and small.identity != gallery.identity
    conf, pairs = method_conf("xfeat-lighterglue"), mapping.MappingConfig(num_pairs=3)
    assert mapping.pools_matching(conf) and not mapping.pools_matching(method_conf("sift"))
    monkeypatch.setattr(mapping, "MATCH_CHUNK", 4)  # several chunks in flight at once
    monkeypatch.setattr(mapping, "EXTRACT_CHUNK", 3)
    alone = mapping.build_map(small, conf, tmp_path / "alone", pairs)
    pools, real_pool = [], mapping.MatchPool
    monkeypatch.setattr(mapping, "MatchPool", lambda ex, n: pools.append(n) or real_pool(ex, n))

    def not_here(name: str) -> None:
        raise AssertionError(f"{name} loaded in the driver: the pool should extract and match")

    monkeypatch.setattr(mapping, "build_features", not_here)
    monkeypatch.setattr(mapping, "build_matcher", not_here)
    pooled = [str(small.root), "--method", "xfeat-lighterglue", "--num-pairs", "3"]
    assert main(["build-map", *pooled, "--workers", "2", "--out", str(tmp_path / "pooled")]) == 0
    assert pools == [2]
    report = mapping.build_map(small, conf, tmp_path / "pooled", pairs)  # finished: its report
    assert report.points == alone.points > 100 and report.pairs == alone.pairs
    for name, count in (("features.h5", len(small)), ("matches.h5", alone.pairs)):
        with h5py.File(tmp_path / "alone" / name) as a, h5py.File(tmp_path / "pooled" / name) as b:
            assert sorted(a) == sorted(b) and len(a) == count
            assert all(_same_h5(a[k], b[k]) for k in a)


def _same_h5(a: object, b: object) -> bool:
    """Whether two HDF5 datasets, or groups of them, hold the same arrays."""
    import h5py

    if isinstance(a, h5py.Group) and isinstance(b, h5py.Group):
        return sorted(a) == sorted(b) and all(_same_h5(a[k], b[k]) for k in a)
    assert isinstance(a, h5py.Dataset) and isinstance(b, h5py.Dataset)
    return np.array_equal(a[()], b[()])
