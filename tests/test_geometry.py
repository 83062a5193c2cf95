import numpy as np

from vlocbench.geometry import covariance_through_offset, make_pose, rot_z


def test_a_rotation_error_moves_an_offset_frame_by_its_lever_arm():
    world_from_a = make_pose(rot_z(np.pi / 2), np.array([10.0, 5.0, 0.0]))
    a_from_b = make_pose(np.eye(3), np.array([2.0, 0.0, 0.0]))  # b 2 m ahead of a: world +y
    yaw_only = np.diag([0.0, 0.0, 0.0, 0.0, 0.0, 0.01])  # rad^2 about the world's z
    moved = covariance_through_offset(yaw_only, world_from_a, a_from_b)
    assert np.allclose(np.diag(moved), [0.04, 0.0, 0.0, 0.0, 0.0, 0.01])  # (2 m)^2 * 0.01 along x
    assert np.isclose(moved[0, 5], -0.02)  # turning left moves b towards -x
    position_only = np.diag([1.0, 2.0, 3.0, 0.0, 0.0, 0.0])
    assert np.allclose(
        covariance_through_offset(position_only, world_from_a, a_from_b), position_only
    )
