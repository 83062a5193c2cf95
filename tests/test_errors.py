import pickle

import pytest

from vlocbench.errors import (
    ConfigError,
    LocalizationError,
    PlanningError,
    RenderBackendError,
    UnknownNameError,
)


@pytest.mark.parametrize(
    "error",
    [
        ConfigError("ekf.mahalanobis_gate", "must be > 0"),
        UnknownNameError("method", "sfit", ["sift", "orb-teblid"]),
        LocalizationError("too few matches"),
        PlanningError("no path"),
        RenderBackendError("no EGL"),
    ],
)
def test_errors_cross_a_process_boundary_intact(error):
    """Pool workers send their exceptions to the driver pickled: each arrives as itself, with its
    message (not as a broken pool)."""
    again = pickle.loads(pickle.dumps(error))
    assert type(again) is type(error) and str(again) == str(error)
    assert vars(again) == vars(error)
