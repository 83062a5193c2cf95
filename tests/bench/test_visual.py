import numpy as np
import pytest

from tests.conftest import CAMERA
from vlocbench.bench import EpisodeConfig, run_episode
from vlocbench.bench.visual import VisualLocalizer
from vlocbench.sim import Simulator


def test_visual_localizer_in_a_ground_truth_episode(small_town, stretch, sift_map):
    localizer = VisualLocalizer(sift_map[0], (CAMERA,), name="sift")
    with Simulator(small_town) as sim:
        r = run_episode(sim, stretch, localizer, EpisodeConfig(mode="ground_truth"))
    assert r.completed and r.localizer == "sift"
    recs = r.localizations
    assert len(recs) >= 25
    pos = np.array([x.position_error_m for x in recs if x.success])
    assert len(pos) >= 0.9 * len(recs)
    assert np.median(pos) < 0.1
    assert np.mean(pos < 0.5) > 0.8
    assert all(x.compute_time_s > 0 for x in recs)
    # its time by stage, together within the time it took, and the report's mean per stage
    from vlocbench.bench.metrics import MAP_STAGES, episode_metrics

    assert all(set(x.stage_s) == set(MAP_STAGES) for x in recs if x.success)
    assert all(0 < sum(x.stage_s.values()) <= x.compute_time_s for x in recs)
    extra = episode_metrics(r).extra
    assert extra["ct_matching_ms"] == pytest.approx(
        1000 * np.mean([x.stage_s.get("matching", 0.0) for x in recs])
    )
    assert 0 < extra["ct_features_ms"] <= 1000 * np.mean([x.compute_time_s for x in recs])
    # each answer keeps its PnP inlier count (what localizer.min_inliers would compare), a failure 0
    assert all(x.inliers >= 4 if x.success else x.inliers == 0 for x in recs)
    # the vehicle pose comes through the camera's mounting: the yaw is the car's, not the camera's
    assert np.median([x.yaw_error_deg for x in recs if x.success]) < 1.0


def test_a_two_camera_rig_in_a_ground_truth_episode(small_town, stretch, sift_map):
    from vlocbench.sim import Camera, Extrinsics

    back = Camera("right-back", CAMERA.intrinsics, Extrinsics(x_m=0.0, yaw_deg=-70.0))
    localizer = VisualLocalizer(sift_map[0], (CAMERA, back), name="sift-rig")
    with Simulator(small_town) as sim:
        r = run_episode(sim, stretch.head(30.0), localizer, EpisodeConfig(mode="ground_truth"))
    ok = [x for x in r.localizations if x.success]
    assert len(ok) >= 0.9 * len(r.localizations) >= 9
    assert np.median([x.position_error_m for x in ok]) < 0.1
    assert np.median([x.yaw_error_deg for x in ok]) < 1.0


def test_sequential_localization_from_the_ekf_prior_navigates(
    small_town, stretch, gallery, tmp_path
):
    from vlocbench.loc.mapping import build_map
    from vlocbench.loc.registry import method_conf

    build_map(gallery, method_conf("sift-prior"), tmp_path / "prior")
    localizer = VisualLocalizer(tmp_path / "prior", (CAMERA,), name="sift-prior")
    with Simulator(small_town) as sim:
        r = run_episode(sim, stretch, localizer, EpisodeConfig(seed=3))
    assert r.completed
    ok = [x for x in r.localizations if x.success]
    assert len(ok) >= 0.8 * len(r.localizations) >= 18  # 60 m at 4-5 m/s, 2 Hz
    assert np.median([x.position_error_m for x in ok]) < 0.1
    # the paper's filter applies each pose 0.2 s late at the current state: it lags that far
    lag_m = 0.2 * r.trajectory.speed_mps.max()
    assert np.median(r.trajectory.ekf_position_error_m) < lag_m + 0.5
    # At 320x240 the shaded panel walls of this stretch give PnP answers from 4-8 inliers, some
    # 3-6 m and 60-125 deg off, and the paper's filter fuses them (Mahalanobis gate 20): 0-2
    # crashes a seed on scene 7. What must hold is that such an answer, never the prior-driven
    # pipeline itself, is what throws the car off: each failure follows one within 3 s.
    wrong = [x.time_s for x in ok if x.fused and (x.position_error_m > 1 or x.yaw_error_deg > 10)]
    for failure in r.reinitializations:
        assert any(failure.time_s - 3.0 <= t <= failure.time_s for t in wrong), failure


def test_a_failed_attempt_reports_its_stages(sift_map):
    """A black image finds nothing, and says how long each stage it ran took."""
    from vlocbench.bench import LocalizationQuery
    from vlocbench.sim import Frame

    localizer = VisualLocalizer(sift_map[0], (CAMERA,), name="sift")
    i = CAMERA.intrinsics
    black = Frame(CAMERA, np.zeros((i.height, i.width, 3), np.uint8), np.eye(4), 0.0)
    e = localizer.localize(LocalizationQuery(0.0, (black,), np.eye(4)))
    assert not e.success and e.reason
    assert e.stage_s["features"] > 0


def test_a_retrieved_image_is_placed_where_the_gallery_car_stood(small_town, stretch, sift_map):
    """Place recognition scores a retrieved image by where the gallery's car stood: with the
    query camera raised by 4 m and tilted down, that is still on the ground along the gallery's
    drive (the query's mount would put the car 4 m under the road and metres aside)."""
    from vlocbench.bench import LocalizationQuery

    localizer = VisualLocalizer(sift_map[0], (CAMERA,), name="sift")
    x, y, yaw = (float(v) for v in (*stretch.xy[10], stretch.yaw_rad[10]))
    with Simulator(small_town) as sim:
        truth = sim.teleport(x, y, yaw).world_from_vehicle()
        frames = tuple(sim.render([CAMERA.offset(4.0, 22.5)]))
    e = localizer.localize(LocalizationQuery(0.0, frames, truth))
    stood = np.asarray(e.ranked_xyz_m)
    assert len(stood) >= 5
    assert np.allclose(stood[:, 2], truth[2, 3], atol=0.01)  # on the ground, as the truth
    # on the gallery's drive: within a few centimetres of the route's polyline
    a, b = stretch.xy[:-1], stretch.xy[1:]
    t = np.einsum("psk,sk->ps", stood[:, None, :2] - a, b - a) / np.sum((b - a) ** 2, axis=1)
    foot = a + np.clip(t, 0, 1)[..., None] * (b - a)
    assert np.linalg.norm(stood[:, None, :2] - foot, axis=2).min(axis=1).max() < 0.05


def test_answers_carry_the_pnp_covariance_when_asked(small_town, stretch, sift_map):
    """``localizer: {covariance: estimate}``: each answer carries the PnP's covariance of the
    vehicle's (x, y, yaw), scaled by the image noise it assumes; the default carries none (the
    filter's fixed 0.1, the paper's)."""
    from vlocbench.bench import LocalizationQuery
    from vlocbench.loc.localizer import LocalizerConfig

    x, y, yaw = (float(v) for v in (*stretch.xy[10], stretch.yaw_rad[10]))
    with Simulator(small_town) as sim:
        truth = sim.teleport(x, y, yaw).world_from_vehicle()
        query = LocalizationQuery(0.0, tuple(sim.render([CAMERA])), truth)
    answers = {
        config: VisualLocalizer(sift_map[0], (CAMERA,), config, "sift").localize(query)
        for config in (
            LocalizerConfig(),
            LocalizerConfig(covariance="estimate"),
            LocalizerConfig(covariance="estimate", pixel_noise_px=2.0),
        )
    }
    fixed, one_px, two_px = answers.values()
    assert fixed.success and fixed.covariance is None
    cov = np.asarray(one_px.covariance)
    assert cov.shape == (3, 3) and np.allclose(cov, cov.T)
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    # a good view pins the car within centimetres and a fraction of a degree, far tighter than
    # the paper's 0.1 m^2 and 0.1 rad^2
    assert np.sqrt(cov[0, 0] + cov[1, 1]) < 0.3 and np.degrees(np.sqrt(cov[2, 2])) < 1.0
    assert np.allclose(np.asarray(two_px.covariance), 4.0 * cov)


def test_an_unknown_covariance_lists_the_valid_ones():
    from vlocbench.errors import UnknownNameError
    from vlocbench.loc.localizer import LocalizerConfig

    with pytest.raises(UnknownNameError, match=r"localizer\.covariance.*estimate"):
        LocalizerConfig(covariance="honest")
    with pytest.raises(ValueError, match=r"localizer\.pixel_noise_px"):
        LocalizerConfig(covariance="estimate", pixel_noise_px=0.0)
