import numpy as np
import pytest

from vlocbench.config import from_dict
from vlocbench.errors import ConfigError
from vlocbench.nav import Ekf, EkfConfig, OdometryNoise, PoseMeasurement, WheelOdometry
from vlocbench.nav.ekf import VLOCBENCH_EKF
from vlocbench.nav.odometry import integrate_planar

REPLAY = EkfConfig(late_measurements="replay")

DT = 0.05


def _truth(n, v=4.0, w=0.05):
    poses = [(0.0, 0.0, 0.0)]
    for _ in range(n):
        poses.append(integrate_planar(*poses[-1], v, w, DT))
    return np.array(poses)


def _measure(pose, t, var=0.1):
    return PoseMeasurement(t, *pose, np.diag([var, var, var]))


@pytest.mark.parametrize("config", [EkfConfig(), VLOCBENCH_EKF], ids=["paper", "vlocbench"])
def test_converges_to_perfect_measurements_from_a_wrong_start(config):
    truth = _truth(400)
    ekf = Ekf(config)
    ekf.reset(3.0, -2.0, 0.2, 0.0)
    odo = WheelOdometry(OdometryNoise(), seed=0)
    for k in range(400):
        ekf.predict(odo.read(4.0, 0.05), DT)
        if (k + 1) % 10 == 0:  # 2 Hz
            assert ekf.update(_measure(truth[k + 1], (k + 1) * DT)).accepted
    x, y, yaw = ekf.pose
    assert np.hypot(x - truth[-1, 0], y - truth[-1, 1]) < 0.3
    assert abs(yaw - truth[-1, 2]) < np.radians(2)
    assert ekf.x[3] == pytest.approx(4.0, abs=0.5)


@pytest.mark.parametrize("config", [EkfConfig(), VLOCBENCH_EKF], ids=["paper", "vlocbench"])
def test_odometry_alone_grows_the_covariance_and_a_fix_shrinks_it(config):
    ekf = Ekf(config)
    odo = WheelOdometry(seed=0)
    p0 = np.trace(ekf.P[:2, :2])
    for _ in range(100):
        ekf.predict(odo.read(4.0, 0.0), DT)
    p1 = np.trace(ekf.P[:2, :2])
    assert p1 > p0
    ekf.update(_measure(ekf.pose, ekf.time_s, 0.01))
    assert np.trace(ekf.P[:2, :2]) < p1
    assert np.all(np.linalg.eigvalsh(ekf.P) > -1e-12)


def test_twist_fusion_filters_the_speed_and_input_fusion_takes_the_reading():
    twist, inp = Ekf(), Ekf(VLOCBENCH_EKF)
    odo = WheelOdometry(seed=1)
    speeds, readings = [], []
    for _ in range(400):
        r = odo.read(4.0, 0.0)
        twist.predict(r, DT)
        inp.predict(r, DT)
        assert inp.speed_mps == r.speed_mps
        speeds.append(twist.speed_mps)
        readings.append(r.speed_mps)
    assert np.mean(speeds[200:]) == pytest.approx(4.0, abs=0.05)
    assert np.std(speeds[200:]) < 0.4 * np.std(readings[200:])


def test_the_paper_filter_trusts_a_fix_far_more_than_vlocbench_own():
    """Gain on x of a 2 Hz fix in steady state: about 0.4 in the paper's filter (its process
    noise 0.05 m^2/s against a pose variance of 0.1), small in the motion-trusting option."""
    gains = {}
    for name, config in (("paper", EkfConfig()), ("vlocbench", VLOCBENCH_EKF)):
        ekf, odo = Ekf(config), WheelOdometry(seed=0)
        for k in range(200):
            ekf.predict(odo.read(4.0, 0.0), DT)
            if (k + 1) % 10 == 0:
                px = ekf.P[0, 0]  # just before the fix
                ekf.update(_measure(ekf.pose, ekf.time_s))
        gains[name] = px / (px + 0.1)
    assert 0.3 < gains["paper"] < 0.6
    assert gains["vlocbench"] < 0.2


def test_a_50_m_outlier_is_rejected_by_either_gate():
    for config in (
        EkfConfig(),  # the paper's: Mahalanobis 20 alone
        EkfConfig(mahalanobis_gate=None, metric_gate_m=20.0),
        EkfConfig(metric_gate_m=20.0),
    ):
        ekf = Ekf(config)
        ekf.reset(10.0, 0.0, 0.0, 0.0)
        ekf.predict(WheelOdometry(seed=0).read(4.0, 0.0), DT)
        before = ekf.x.copy()
        out = ekf.update(_measure((60.0, 0.0, 0.0), DT))
        assert not out.accepted and out.reason
        assert np.array_equal(ekf.x, before)
    ekf = Ekf(EkfConfig(mahalanobis_gate=None))
    ekf.reset(10.0, 0.0, 0.0, 0.0)
    for _ in range(20):  # 1 s without a fix: the paper's process noise makes it uncertain
        ekf.predict(WheelOdometry(seed=0).read(0.0, 0.0), DT)
    assert ekf.update(_measure((60.0, 0.0, 0.0), 1.0, var=1e-4)).accepted  # ungated: it jumps
    assert ekf.pose[0] > 55


def test_a_late_measurement_lands_as_if_it_had_come_on_time():
    truth = _truth(60)
    odo = WheelOdometry(seed=3)
    readings = [odo.read(4.0, 0.05) for _ in range(60)]
    fix = _measure(truth[20] + [0.5, -0.3, 0.02], 20 * DT)
    on_time, late = Ekf(REPLAY), Ekf(REPLAY)
    for k, r in enumerate(readings):
        on_time.predict(r, DT)
        late.predict(r, DT)
        if k + 1 == 20:
            on_time.update(fix)
        if k + 1 == 28:  # 0.4 s late, stamped with its image time
            assert late.update(fix).accepted
    assert np.allclose(on_time.x, late.x, atol=1e-9)
    assert np.allclose(on_time.P, late.P, atol=1e-12)
    # the paper's filter (smooth_lagged_data off) corrects the current state with it instead:
    # exactly as a fix stamped now, and measurably different from one applied at its stamp
    current, now = Ekf(), Ekf()
    for k, r in enumerate(readings):
        current.predict(r, DT)
        now.predict(r, DT)
        if k + 1 == 28:
            assert current.update(fix).accepted
            now.update(PoseMeasurement((k + 1) * DT, fix.x_m, fix.y_m, fix.yaw_rad, fix.covariance))
    assert np.array_equal(current.x, now.x)
    assert np.hypot(*(current.x[:2] - on_time.x[:2])) > 0.1


def test_measurements_too_old_or_from_the_future():
    ekf = Ekf(EkfConfig(history_s=1.0, late_measurements="replay"))
    for _ in range(100):  # 5 s
        ekf.predict(WheelOdometry(seed=0).read(4.0, 0.0), DT)
    out = ekf.update(_measure(ekf.pose, 1.0))
    assert not out.accepted and "older" in out.reason
    with pytest.raises(ValueError, match="future"):
        ekf.update(_measure(ekf.pose, ekf.time_s + 1.0))
    ekf.reset(0, 0, 0, 10.0)
    assert "older" in ekf.update(_measure((0, 0, 0), 9.0)).reason


def test_bad_config():
    with pytest.raises(ConfigError, match=r"ekf\.mahalanobis_gate"):
        EkfConfig(mahalanobis_gate=0)
    with pytest.raises(ConfigError, match="unknown odometry_fusion 'imu'; valid: input, twist"):
        from_dict(EkfConfig, {"odometry_fusion": "imu"})
    with pytest.raises(ConfigError, match="valid: current, replay"):
        from_dict(EkfConfig, {"late_measurements": "smooth"})
