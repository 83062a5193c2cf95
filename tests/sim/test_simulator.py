import numpy as np
import pytest

from vlocbench.sim import Conditions, Control, Simulator, Traffic


def test_driving_into_a_wall_reports_a_building_collision(small_sim, small_town):
    # from the route start (eastbound, south ring road), steer hard right towards the buildings
    wp, yaw = small_town.route.waypoints_xy[0], small_town.route.yaw_rad[0]
    small_sim.teleport(float(wp[0]), float(wp[1]), float(yaw) - np.pi / 2)
    events = []
    for _ in range(200):
        events += small_sim.step(Control(throttle=0.6)).collisions
        if any(e.category == "building" for e in events):
            break
    categories = [e.category for e in events]
    assert "curb" in categories and "building" in categories, events
    first = events[0]
    assert first.time_s > 0 and np.hypot(first.x_m - wp[0], first.y_m - wp[1]) < 15


def test_staying_on_the_road_is_collision_free_and_teleport_resets(small_sim, small_town):
    wp, yaw = small_town.route.waypoints_xy[0], small_town.route.yaw_rad[0]
    state = small_sim.teleport(float(wp[0]), float(wp[1]), float(yaw))
    assert state.speed_mps == 0.0
    for _ in range(60):
        result = small_sim.step(Control(throttle=0.3))
        assert result.collisions == ()
    assert result.state.speed_mps > 1.0
    np.testing.assert_allclose(result.state.y_m, wp[1], atol=1e-6)


def test_traffic_moves_deterministically(small_town):
    def run():
        with Simulator(
            small_town, Conditions(traffic=Traffic(cars=3, pedestrians=4, seed=2))
        ) as sim:
            start = sim.traffic.car_poses() + sim.traffic.pedestrian_poses()
            for _ in range(40):
                sim.step(Control())
            end = sim.traffic.car_poses() + sim.traffic.pedestrian_poses()
        return np.array(start), np.array(end)

    (s1, e1), (_s2, e2) = run(), run()
    np.testing.assert_array_equal(e1, e2)
    moved = np.linalg.norm(e1[:, :2] - s1[:, :2], axis=1)
    assert (moved > 1.0).sum() >= 5  # cars ~6 m/s, pedestrians ~1.3 m/s over 2 s


def test_reset_restarts_time_and_traffic(small_town):
    with Simulator(small_town, Conditions(traffic=Traffic(cars=3, pedestrians=2, seed=4))) as sim:
        x, y = small_town.route.waypoints_xy[0]
        yaw = float(small_town.route.yaw_rad[0])

        def drive():
            state = sim.reset(float(x), float(y), yaw)
            assert state.time_s == 0.0 and state.speed_mps == 0.0
            for _ in range(30):
                sim.step(Control(throttle=0.3))
            return sim.state, np.array(sim.traffic.car_poses() + sim.traffic.pedestrian_poses())

        (a_state, a_traffic), (b_state, b_traffic) = drive(), drive()
        assert a_state == b_state and a_state.time_s == pytest.approx(1.5)
        np.testing.assert_array_equal(a_traffic, b_traffic)


def test_a_traffic_car_is_a_collision_target(small_town):
    with Simulator(small_town, Conditions(traffic=Traffic(cars=1, seed=0))) as sim:
        x, y, yaw = sim.traffic.car_poses()[0]
        sim.teleport(x - 8 * np.cos(yaw), y - 8 * np.sin(yaw), yaw)
        categories = set()
        for _ in range(100):
            categories |= {e.category for e in sim.step(Control(throttle=1.0)).collisions}
        assert "car" in categories


def test_more_traffic_than_the_scene_holds_is_refused_and_changes_nothing(small_sim):
    from vlocbench.errors import ConfigError

    before = (small_sim.conditions, small_sim.traffic)
    with pytest.raises(ConfigError, match="traffic"):
        small_sim.set_conditions(Conditions(traffic=Traffic(cars=3)))
    assert (small_sim.conditions, small_sim.traffic) == before


def test_the_towns_edge_is_a_wall_no_camera_draws(small_sim, small_town, monkeypatch):
    from vlocbench.sim import Camera, Extrinsics, Intrinsics
    from vlocbench.sim.scene import _SceneBuilder

    # a car 10 m outside the town's east edge, driving towards it: nothing else lies out there
    _, y0, x1, y1 = small_town.extent
    start = (x1 + 10.0, (y0 + y1) / 2, np.pi)
    small_sim.teleport(*start)
    events = []
    for _ in range(100):
        events += small_sim.step(Control(throttle=0.6)).collisions
        if events:
            break
    assert [e.category for e in events] == ["edge"], events
    assert x1 <= events[0].x_m < x1 + 5.0
    # and a camera looking at it sees what it would without it (drawn, it fills a third)
    camera = Camera("front", Intrinsics(160, 120, 90.0), Extrinsics(z_m=1.6, yaw_deg=0.0))
    small_sim.teleport(*start)
    image = small_sim.render([camera], frame_id=1)[0].image
    monkeypatch.setattr(_SceneBuilder, "edge", lambda self: None)
    with Simulator(small_town) as bare:
        bare.teleport(*start)
        assert np.array_equal(bare.render([camera], frame_id=1)[0].image, image)
