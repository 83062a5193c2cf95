import json

import numpy as np
import pytest

from tests.conftest import CAMERA, query_pose
from vlocbench.bench.visual import camera_model
from vlocbench.errors import LocalizationError
from vlocbench.geometry import pose_error
from vlocbench.loc.localizer import LocalizerConfig, MapLocalizer
from vlocbench.sim import Simulator


@pytest.fixture(scope="module")
def sim(small_town):
    with Simulator(small_town) as s:
        yield s


def _render(sim, pose):
    sim.teleport(*pose)
    return sim.render([CAMERA])[0]


def test_map_is_triangulated_from_the_known_poses(gallery, sift_map):
    _, report = sift_map
    assert report.images == len(gallery) >= 25
    assert report.points > 200  # 285 (scene 6); about 500 with the sidewalks' grout lines
    assert report.mean_track_length > 2.5
    assert report.mean_reprojection_error_px < 1.0


def test_query_between_gallery_images_is_localized(sim, stretch, sift_map):
    localizer = MapLocalizer(sift_map[0])
    for index in (8, 24):  # mid-block (at crossings the camera sees only distant facades)
        frame = _render(sim, query_pose(stretch, index))
        result = localizer.localize(frame.image, camera_model(CAMERA))
        assert result.success, result.reason
        dt, dr = pose_error(result.world_from_cam, frame.world_from_cam)
        assert dt < 0.25 and dr < 2.0
        assert result.num_inliers >= 30
        assert set(result.seconds) == {"features", "retrieval", "matching", "pnp"}
        # retrieval returns neighbours: gallery images taken within 6 m of the query
        gallery_xy = {m.name: m.world_from_cam[:3, 3] for m in localizer.images}
        near = [
            np.linalg.norm(gallery_xy[n] - frame.world_from_cam[:3, 3]) for n in result.retrieved
        ]
        assert min(near) < 3.0 and sum(d < 6.0 for d in near) >= 3


def test_a_point_seen_by_several_retrieved_images_is_one_correspondence(sim, stretch, sift_map):
    localizer = MapLocalizer(sift_map[0])
    frame = _render(sim, query_pose(stretch, 8))
    result, corr = localizer._solve(frame.image, camera_model(CAMERA), None)
    assert result.success and corr is not None, result.reason
    feats = localizer.extractor.extract(frame.image)
    by_name = {m.name: m for m in localizer.images}
    matched = []  # every (query keypoint, 3D point) the cluster's images give, repeats included
    for name in result.cluster:
        m = localizer.matcher.match(feats, by_name[name].features)
        matched += [(int(q), int(p)) for q, p in zip(m[:, 0], by_name[name].point_ids[m[:, 1]])]
    assert len(result.cluster) >= 3 and len(set(matched)) < 0.8 * len(matched)
    # hloc's rule: each pair once, in the order first matched
    assert len(corr.points2D) == result.num_correspondences == len(set(matched))
    first = list(dict.fromkeys(matched))
    assert np.allclose(corr.points2D, feats.keypoints[[q for q, _ in first]] + 0.5)
    assert np.allclose(corr.points3D, [localizer.points3D[p] for _, p in first])
    assert result.num_inliers <= len(set(matched))


def test_confident_pose_stops_matching_early(sim, stretch, sift_map):
    frame = _render(sim, query_pose(stretch, 8))
    every = MapLocalizer(sift_map[0]).localize(frame.image, camera_model(CAMERA))
    early = MapLocalizer(sift_map[0], LocalizerConfig(confident_inliers=20)).localize(
        frame.image, camera_model(CAMERA)
    )
    assert every.success and early.success, (every.reason, early.reason)
    # the best-ranked image alone gives a confident pose: the other four are never matched
    assert early.cluster == every.retrieved[:1] and len(every.cluster) > 1
    assert 20 <= early.num_inliers < every.num_inliers
    dt, dr = pose_error(early.world_from_cam, frame.world_from_cam)
    assert dt < 0.25 and dr < 2.0


def test_unmapped_place_and_featureless_image_fail_cleanly(sim, small_town, sift_map):
    localizer = MapLocalizer(sift_map[0])
    black = np.zeros((240, 320, 3), np.uint8)
    result = localizer.localize(black, camera_model(CAMERA))
    assert not result.success and "features" in result.reason
    # the north road, looking away from anything the gallery saw
    x, y = small_town.route.waypoints_xy[-1]
    frame = _render(sim, (float(x), float(y), float(small_town.route.yaw_rad[-1])))
    result = localizer.localize(frame.image, camera_model(CAMERA))
    if result.success:  # a wrong answer must at least not be near a gallery place by accident
        assert pose_error(result.world_from_cam, frame.world_from_cam)[0] > 0.25
    else:
        assert result.reason
    # the explicit fall-back answers the best retrieved image's pose, and says so
    fallback = MapLocalizer(sift_map[0], LocalizerConfig(fallback_to_retrieval=True))
    result = fallback.localize(black, camera_model(CAMERA))
    assert result.success and result.fallback and result.reason


def test_pose_prior_retrieval(sim, stretch, gallery, tmp_path):
    from vlocbench.loc.mapping import build_map
    from vlocbench.loc.registry import method_conf

    out = tmp_path / "prior"
    build_map(gallery, method_conf("sift-prior"), out)
    localizer = MapLocalizer(out)
    assert localizer.needs_prior
    frame = _render(sim, query_pose(stretch, 12))
    with pytest.raises(LocalizationError, match="prior"):
        localizer.localize(frame.image, camera_model(CAMERA))
    prior = frame.world_from_cam.copy()
    prior[:3, 3] += [1.5, -1.0, 0.0]  # a prior a couple of metres off
    result = localizer.localize(frame.image, camera_model(CAMERA), prior)
    assert result.success
    assert pose_error(result.world_from_cam, frame.world_from_cam)[0] < 0.25


def test_pose_prior_retrieval_on_a_map_with_its_own_retrieval(sim, stretch, sift_map):
    frame = _render(sim, query_pose(stretch, 12))
    own = MapLocalizer(sift_map[0])
    prior_only = MapLocalizer(sift_map[0], LocalizerConfig(retrieval="pose-prior"))
    assert not own.needs_prior and prior_only.needs_prior
    with pytest.raises(LocalizationError, match="prior"):
        prior_only.localize(frame.image, camera_model(CAMERA))
    gallery_xy = {m.name: m.world_from_cam[:3, 3] for m in own.images}
    # a prior elsewhere on the stretch: the retrieved images are the ones nearest to it, not to
    # the image, which the map's own retrieval finds
    elsewhere = _render(sim, query_pose(stretch, 24)).world_from_cam
    result = prior_only.localize(frame.image, camera_model(CAMERA), elsewhere)
    assert all(np.linalg.norm(gallery_xy[n] - elsewhere[:3, 3]) < 6.0 for n in result.retrieved)
    result = own.localize(frame.image, camera_model(CAMERA), elsewhere)
    truth_xy = frame.world_from_cam[:3, 3]
    assert min(np.linalg.norm(gallery_xy[n] - truth_xy) for n in result.retrieved) < 3.0
    result = prior_only.localize(frame.image, camera_model(CAMERA), frame.world_from_cam)
    assert result.success
    assert pose_error(result.world_from_cam, frame.world_from_cam)[0] < 0.25


def test_bad_query_images_are_clearpose_error(sift_map):
    localizer = MapLocalizer(sift_map[0])
    cam = camera_model(CAMERA)
    with pytest.raises(LocalizationError, match="320x240"):
        localizer.localize(np.zeros((100, 100, 3), np.uint8), cam)
    with pytest.raises(LocalizationError, match=r"\(H, W, 3\)"):
        localizer.localize(np.zeros((240, 320), np.uint8), cam)
    with pytest.raises(LocalizationError, match="uint8"):
        localizer.localize(np.zeros((240, 320, 3), np.float32), cam)


def test_corrupt_map_files_are_clearpose_error(sift_map, tmp_path):
    import shutil

    broken = tmp_path / "broken"
    shutil.copytree(sift_map[0], broken)
    (broken / "map.json").write_text("{not json")
    with pytest.raises(LocalizationError, match="corrupt"):
        MapLocalizer(broken)
    shutil.copy(sift_map[0] / "map.json", broken / "map.json")
    (broken / "features.h5").write_bytes(b"garbage")
    with pytest.raises(LocalizationError, match="corrupt"):
        MapLocalizer(broken)
    shutil.copy(sift_map[0] / "features.h5", broken / "features.h5")
    for model_file in (broken / "sfm").iterdir():
        model_file.write_bytes(b"\x00" * 7)
    with pytest.raises(LocalizationError, match=r"unreadable|no 3D points"):
        MapLocalizer(broken)
    with pytest.raises(LocalizationError, match="not a map"):
        MapLocalizer(tmp_path / "nowhere")
    info = json.loads((sift_map[0] / "map.json").read_text())
    assert info["method"] == {"features": "sift", "matcher": "nn-ratio", "retrieval": "vlad"}


def test_bad_localizer_and_mapping_configs():
    from vlocbench.errors import ConfigError
    from vlocbench.loc.mapping import MappingConfig

    with pytest.raises(ConfigError, match=r"localizer\.top_k"):
        LocalizerConfig(top_k=0)
    with pytest.raises(ConfigError, match=r"localizer\.min_inliers"):
        LocalizerConfig(min_inliers=3)
    with pytest.raises(ConfigError, match="confident_inliers"):
        LocalizerConfig(confident_inliers=-1)
    with pytest.raises(ConfigError, match=r"localizer\.retrieval.*valid: map, pose-prior"):
        LocalizerConfig(retrieval="gps")
    with pytest.raises(ConfigError, match=r"mapping\.pairs.*valid: poses, retrieval"):
        MappingConfig(pairs="random")
    with pytest.raises(ConfigError, match=r"mapping\.verification.*valid: epipolar, sampson"):
        MappingConfig(verification="none")


def test_a_rig_is_localized_by_one_generalized_pnp(sim, stretch, sift_map):
    from vlocbench.sim import Camera, Extrinsics

    back = Camera("right-back", CAMERA.intrinsics, Extrinsics(x_m=0.0, yaw_deg=-70.0))
    rig = (CAMERA, back)
    sim.teleport(*query_pose(stretch, 8))
    frames = sim.render(list(rig))
    world_from_vehicle = sim.state.world_from_vehicle()
    localizer = MapLocalizer(sift_map[0])
    models = [camera_model(c) for c in rig]
    mounts = [c.extrinsics.vehicle_from_cam() for c in rig]
    result = localizer.localize_rig([f.image for f in frames], models, mounts)
    assert result.success and result.generalized, result.reason
    assert all(r.success for r in result.cameras)
    assert result.num_inliers > max(r.num_inliers for r in result.cameras)
    dt, dr = pose_error(result.world_from_rig, world_from_vehicle)
    assert dt < 0.25 and dr < 2.0
    assert set(result.seconds) == {"features", "retrieval", "matching", "pnp"}
    # a blind camera: the other one's pose, through its mounting
    black = np.zeros_like(frames[0].image)
    one = localizer.localize_rig([black, frames[1].image], models, mounts)
    assert one.success and not one.generalized and not one.cameras[0].success
    dt, dr = pose_error(one.world_from_rig, world_from_vehicle)
    assert dt < 0.25 and dr < 2.0
    blind = localizer.localize_rig([black, black], models, mounts)
    assert not blind.success and "camera 0: only 0 features" in blind.reason
    with pytest.raises(LocalizationError, match="one image, camera and mounting per camera"):
        localizer.localize_rig([black], models, mounts)


def test_the_pnp_covariance_in_the_world_frame_matches_the_spread_of_noisy_answers():
    """Monte Carlo: PnP on 1 px noisy projections of known points; the spread of the answers'
    camera centres and world-side rotations has the shape of ``world_covariance``'s prediction
    (pycolmap's robust loss makes it about 1.5x conservative, the same factor everywhere)."""
    import cv2
    import pycolmap

    from vlocbench.geometry import invert_pose, make_pose, rpy_to_matrix
    from vlocbench.loc.localizer import world_covariance
    from vlocbench.loc.mapping import pose_of

    rng = np.random.default_rng(0)
    cam = pycolmap.Camera(model="PINHOLE", width=800, height=600, params=[400, 400, 400, 300])
    cam_from_world = make_pose(rpy_to_matrix(0.1, -0.3, 1.2), np.array([4.0, -1.0, 20.0]))
    points_cam = rng.uniform([-10, -5, 5], [10, 5, 30], (60, 3))
    points_world = (invert_pose(cam_from_world) @ np.c_[points_cam, np.ones(60)].T).T[:, :3]
    pixels = points_cam[:, :2] / points_cam[:, 2:] * 400 + [400, 300]
    true_world_from_cam = invert_pose(cam_from_world)
    errors, predicted = [], []
    for _ in range(300):
        answer = pycolmap.estimate_and_refine_absolute_pose(
            pixels + rng.normal(0, 1.0, pixels.shape), points_world, cam, return_covariance=True
        )
        estimate = pose_of(answer["cam_from_world"])
        world_from_cam = invert_pose(estimate)
        rotation = cv2.Rodrigues(world_from_cam[:3, :3] @ true_world_from_cam[:3, :3].T)[0]
        errors.append(np.r_[world_from_cam[:3, 3] - true_world_from_cam[:3, 3], rotation.ravel()])
        predicted.append(world_covariance(estimate, answer["covariance"]))
    model = np.mean(predicted, axis=0)
    unit = 1.0 / np.sqrt(np.diag(model))  # compare in standard deviations: metres and radians alike
    sample = np.cov(np.array(errors).T) * np.outer(unit, unit)
    model = model * np.outer(unit, unit)
    scale = np.sum(sample * model) / np.sum(model * model)
    assert 0.4 < scale < 1.0
    assert np.linalg.norm(sample - scale * model) < 0.15 * np.linalg.norm(scale * model)
