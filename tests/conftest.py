"""Shared fixtures: a small town (2x2 blocks) that builds and renders in a fraction of a second."""

from __future__ import annotations

import os
import tempfile

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
# keep anything that might write caches inside a throwaway folder
os.environ.setdefault("MPLCONFIGDIR", tempfile.mkdtemp(prefix="vlocbench-mpl-"))

from vlocbench.sim.town import RouteSpec, TownSpec, generate_town


def small_spec(seed: int = 3) -> TownSpec:
    return TownSpec(
        name="small",
        seed=seed,
        block_widths_m=(50.0, 50.0),
        block_depths_m=(50.0, 50.0),
        border_m=25.0,
        route=RouteSpec(nodes=((0, 0), (2, 0), (2, 2)), start_offset_m=15.0, end_offset_m=15.0),
    )


@pytest.fixture(scope="session")
def small_town():
    return generate_town(small_spec())


@pytest.fixture(scope="session")
def small_sim(small_town):
    from vlocbench.sim import Simulator

    sim = Simulator(small_town)
    yield sim
    sim.close()
