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
        UnknownNameError("key", "bogus", ["min_inliers", "top_k"], field="methods[0].localizer"),
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


def test_an_unknown_key_names_where_it_was_given_once():
    error = UnknownNameError("key", "bogus", ["top_k", "min_inliers"], field="methods[0].localizer")
    assert str(error) == "methods[0].localizer: unknown key 'bogus'; valid: min_inliers, top_k"
    assert error.field == "methods[0].localizer" and error.kind == "key"
