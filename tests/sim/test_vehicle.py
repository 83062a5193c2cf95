import numpy as np
import pytest

from vlocbench.errors import ConfigError
from vlocbench.sim.vehicle import Control, VehicleParams, VehicleState, step_vehicle


def drive(control, seconds, state=None):
    state = state or VehicleState(0.0, 0.0, 0.0)
    params = VehicleParams()
    for _ in range(round(seconds / 0.05)):
        state = step_vehicle(state, control, params, 0.05)
    return state


def test_throttle_accelerates_straight_and_brake_stops():
    s = drive(Control(throttle=1.0), 2.0)
    assert 4.5 < s.speed_mps < 6.0 and abs(s.y_m) < 1e-9 and s.x_m > 4
    stopped = drive(Control(brake=1.0), 2.0, s)
    assert stopped.speed_mps == 0.0


def test_positive_steer_turns_left_on_a_circle_of_the_bicycle_radius():
    s = drive(Control(throttle=0.3, steer=0.5), 6.0)
    assert s.yaw_rate_radps > 0 and s.y_m > 0
    radius = s.speed_mps / s.yaw_rate_radps
    delta = np.radians(70 * 0.5)  # half of the paper car's 70 deg lock
    expected = 2.9 / (np.tan(delta) * np.cos(np.arctan(0.5 * np.tan(delta))))
    assert radius == pytest.approx(expected, rel=0.02)


def test_controls_are_validated():
    with pytest.raises(ConfigError, match=r"control\.steer"):
        Control(steer=1.5)
    with pytest.raises(ConfigError, match=r"control\.throttle"):
        Control(throttle=float("nan"))
