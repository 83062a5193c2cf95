import dataclasses
import signal

import numpy as np
import pytest

from tests.conftest import CAMERA, assert_stops_cleanly
from tests.ros.conftest import start_localize_node
from vlocbench.bench import EpisodeConfig, run_episode
from vlocbench.bench.methods import RosEndpoint
from vlocbench.bench.visual import VisualLocalizer
from vlocbench.ros.remote import RosLocalizer


@pytest.fixture
def node(ros_env, sift_map):
    """Our localization node on the small town's map, in its own process."""
    proc = start_localize_node(sift_map[0], ros_env, localization_frequence=50.0)
    yield proc
    assert_stops_cleanly(proc, signal.SIGINT, 0)


def test_a_ros_node_drives_like_the_same_method_in_process(node, small_sim, stretch, sift_map):
    config = EpisodeConfig(mode="ground_truth", localization_rate_hz=2.0, seed=0)
    local = run_episode(small_sim, stretch, VisualLocalizer(sift_map[0], (CAMERA,)), config)
    remote_localizer = RosLocalizer(RosEndpoint(timeout_s=60.0), (CAMERA,), "ros-sift")
    try:
        remote = run_episode(small_sim, stretch, remote_localizer, config)
        navigate = dataclasses.replace(config, mode="navigate")
        drives = [
            run_episode(small_sim, stretch, loc, navigate)
            for loc in (VisualLocalizer(sift_map[0], (CAMERA,)), remote_localizer)
        ]
    finally:
        remote_localizer.close()
    a, b = local.localizations, remote.localizations
    assert len(a) == len(b) >= 20
    assert [x.success for x in a] == [x.success for x in b]
    assert [x.inliers for x in a] == [x.inliers for x in b] and max(x.inliers for x in b) > 0
    err_a = np.array([x.position_error_3d_m for x in a])
    err_b = np.array([x.position_error_3d_m for x in b])
    np.testing.assert_allclose(err_b, err_a, atol=1e-6, equal_nan=True)  # the same poses
    assert drives[0].failures == drives[1].failures
    np.testing.assert_allclose(
        drives[1].trajectory.true_x_m, drives[0].trajectory.true_x_m, atol=1e-6
    )


def test_a_missing_node_is_a_clear_error(ros_env):
    from vlocbench.bench import LocalizationQuery
    from vlocbench.errors import ConfigError
    from vlocbench.sim import Frame

    loc = RosLocalizer(RosEndpoint(image_topic="nobody_listens", timeout_s=1.0), (CAMERA,), "x")
    try:
        frame = Frame(CAMERA, np.zeros((240, 320, 3), np.uint8), np.eye(4), 0.0)
        with pytest.raises(ConfigError, match="no node subscribes to 'nobody_listens' after 1 s"):
            loc.localize(LocalizationQuery(0.0, (frame,), np.eye(4)))
    finally:
        loc.close()
