import numpy as np
import pytest

from vlocbench.errors import ConfigError
from vlocbench.nav import ControllerConfig, Pid, PidGains, VehicleController
from vlocbench.nav.control import heading_error_rad


def test_pid_terms_and_clipping():
    p = Pid(PidGains(kp=0.5), dt_s=0.1)
    assert p.step(1.0) == pytest.approx(0.5)
    assert p.step(10.0) == 1.0 and p.step(-10.0) == -1.0
    i = Pid(PidGains(kp=0.0, ki=2.0, time_base="second"), dt_s=0.1)
    out = [i.step(1.0) for _ in range(3)]
    assert out == pytest.approx([0.2, 0.4, 0.6])
    # the paper's (CARLA's) time base: the integral sums the errors of the steps
    per_step = Pid(PidGains(kp=0.0, ki=0.2), dt_s=0.1)
    assert [per_step.step(1.0) for _ in range(3)] == pytest.approx([0.2, 0.4, 0.6])
    per_step_d = Pid(PidGains(kp=0.0, kd=0.5), dt_s=0.05, lo=-10, hi=10)
    assert [per_step_d.step(e) for e in (0.0, 1.0, 3.0)] == pytest.approx([0.0, 0.5, 1.0])
    d = Pid(PidGains(kp=0.0, kd=0.1, time_base="second"), dt_s=0.1, lo=-10, hi=10)
    # no kick on the first step, then the slope of a ramp of 1 per step = 10 per s
    assert [d.step(e) for e in (0.0, 1.0, 2.0)] == pytest.approx([0.0, 1.0, 1.0])
    d.reset()
    assert d.step(5.0) == 0.0


def test_integral_is_bounded():
    p = Pid(PidGains(kp=0.0, ki=1.0, integral_limit=0.5), dt_s=0.1)
    for _ in range(100):
        out = p.step(1.0)
    assert out == pytest.approx(0.5)


# vlocbench's own controller options: gains per second, braking, stopping at the goal
BRAKING = ControllerConfig(
    longitudinal=PidGains(0.206, 0.0206, 0.02575, 10.0, "second"),
    max_throttle=0.75,
    brake=True,
    stop_decel_mps2=1.0,
)


def _drive(controller, speed0=0.0, seconds=20.0, dt=0.05, remaining_m=1e9, drag_per_s=0.0):
    """A first-order car: 3 m/s^2 at full throttle, 8 m/s^2 at full brake, 0.15 s lag."""
    c = controller.config
    speed, accel, trace = speed0, 0.0, []
    for _ in range(int(seconds / dt)):
        cmd = controller.step(0.0, 0.0, 0.0, speed, np.array([10.0, 0.0]), remaining_m)
        assert 0 <= cmd.throttle <= c.max_throttle and 0 <= cmd.brake <= c.max_brake
        assert cmd.throttle == 0 or cmd.brake == 0
        assert c.brake or cmd.brake == 0
        accel += (3 * cmd.throttle - 8 * cmd.brake - accel) * dt / 0.15
        speed = max(0.0, speed + (accel - drag_per_s * speed) * dt)
        trace.append(speed)
    return np.array(trace)


def test_paper_controller_reaches_the_target_speed_with_the_throttle_alone():
    up = _drive(VehicleController(ControllerConfig(), 0.05), seconds=30.0, drag_per_s=0.02)
    assert up.max() < 5.0  # the summed integral overshoots, and only drag slows the car down
    assert np.all(np.abs(up[-100:] - 4.0) < 0.15)  # settled within 25 s
    assert 0.5 < np.argmax(up > 3.6) * 0.05 < 2.0


def test_braking_controller_step_response_from_rest_and_from_too_fast():
    up = _drive(VehicleController(BRAKING, 0.05))
    assert up.max() < 4.3  # little overshoot
    assert np.all(np.abs(up[-100:] - 4.0) < 0.15)  # settled within 15 s
    t_90 = np.argmax(up > 3.6) * 0.05
    assert 1.0 < t_90 < 3.0
    down = _drive(VehicleController(BRAKING, 0.05), speed0=8.0)
    assert np.all(np.abs(down[-100:] - 4.0) < 0.15)


def test_paper_controller_drives_through_the_goal():
    assert VehicleController(ControllerConfig(), 0.05).target_speed_mps(0.0) == 4.0


def test_slows_to_a_stop_at_the_goal():
    ctl = VehicleController(BRAKING, 0.05)
    assert ctl.target_speed_mps(100.0) == 4.0
    assert ctl.target_speed_mps(0.5) == pytest.approx(1.0)
    assert ctl.target_speed_mps(0.0) == 0.0
    trace = _drive(ctl, speed0=1.0, seconds=10, remaining_m=0.0)
    assert trace[-1] < 0.05


def test_lateral_control_steers_towards_the_target():
    assert heading_error_rad(0, 0, 0, np.array([10.0, 10.0])) == pytest.approx(np.pi / 4)
    assert heading_error_rad(0, 0, np.pi, np.array([-10.0, 0.1])) < 0  # to the right
    ctl = VehicleController(ControllerConfig(), 0.05)
    left = ctl.step(0, 0, 0, 4.0, np.array([10.0, 2.0]), 100.0)
    assert left.steer == pytest.approx(0.9 * np.arctan2(2, 10))
    right = ctl.step(0, 0, 0, 4.0, np.array([0.0, -10.0]), 100.0)
    assert right.steer == -1.0  # clipped


def test_bad_gains():
    with pytest.raises(ConfigError, match=r"pid\.kp"):
        PidGains(kp=-1)
    with pytest.raises(ConfigError, match="target_speed_mps"):
        ControllerConfig(target_speed_mps=0)
    with pytest.raises(ConfigError, match="time_base"):
        PidGains(kp=1.0, time_base="minute")
