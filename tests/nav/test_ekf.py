import numpy as np
import pytest

from vlocbench.errors import ConfigError
from vlocbench.nav import Ekf, EkfConfig, OdometryNoise, PoseMeasurement, WheelOdometry
from vlocbench.nav.odometry import integrate_planar

DT = 0.05


def _truth(n, v=4.0, w=0.05):
    poses = [(0.0, 0.0, 0.0)]
    for _ in range(n):
        poses.append(integrate_planar(*poses[-1], v, w, DT))
    return np.array(poses)


def _measure(pose, t, var=0.1):
    return PoseMeasurement(t, *pose, np.diag([var, var, var]))


def test_converges_to_perfect_measurements_from_a_wrong_start():
    truth = _truth(400)
    ekf = Ekf()
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


def test_odometry_alone_grows_the_covariance_and_a_fix_shrinks_it():
    ekf = Ekf()
    odo = WheelOdometry(seed=0)
    p0 = np.trace(ekf.P[:2, :2])
    for _ in range(100):
        ekf.predict(odo.read(4.0, 0.0), DT)
    p1 = np.trace(ekf.P[:2, :2])
    assert p1 > p0
    ekf.update(_measure(ekf.pose, ekf.time_s, 0.01))
    assert np.trace(ekf.P[:2, :2]) < p1
    assert np.all(np.linalg.eigvalsh(ekf.P) > -1e-12)


def test_a_50_m_outlier_is_rejected_by_either_gate():
    for config in (EkfConfig(metric_gate_m=None), EkfConfig(mahalanobis_gate=None), EkfConfig()):
        ekf = Ekf(config)
        ekf.reset(10.0, 0.0, 0.0, 0.0)
        ekf.predict(WheelOdometry(seed=0).read(4.0, 0.0), DT)
        before = ekf.x.copy()
        out = ekf.update(_measure((60.0, 0.0, 0.0), DT))
        assert not out.accepted and out.reason
        assert np.array_equal(ekf.x, before)
    ekf = Ekf(EkfConfig(metric_gate_m=None, mahalanobis_gate=None))
    ekf.reset(10.0, 0.0, 0.0, 0.0)
    assert ekf.update(_measure((60.0, 0.0, 0.0), 0.0, var=1e-4)).accepted  # ungated: it jumps
    assert ekf.pose[0] > 55


def test_a_late_measurement_lands_as_if_it_had_come_on_time():
    truth = _truth(60)
    odo = WheelOdometry(seed=3)
    readings = [odo.read(4.0, 0.05) for _ in range(60)]
    fix = _measure(truth[20] + [0.5, -0.3, 0.02], 20 * DT)
    on_time, late = Ekf(), Ekf()
    for k, r in enumerate(readings):
        on_time.predict(r, DT)
        late.predict(r, DT)
        if k + 1 == 20:
            on_time.update(fix)
        if k + 1 == 28:  # 0.4 s late, stamped with its image time
            assert late.update(fix).accepted
    assert np.allclose(on_time.x, late.x, atol=1e-9)
    assert np.allclose(on_time.P, late.P, atol=1e-12)
    # applying it now instead (ignoring the stamp) is measurably different
    naive = Ekf()
    for k, r in enumerate(readings):
        naive.predict(r, DT)
        if k + 1 == 28:
            naive.update(
                PoseMeasurement((k + 1) * DT, fix.x_m, fix.y_m, fix.yaw_rad, fix.covariance)
            )
    assert np.hypot(*(naive.x[:2] - on_time.x[:2])) > 0.1


def test_measurements_too_old_or_from_the_future():
    ekf = Ekf(EkfConfig(history_s=1.0))
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
