"""Shared fixtures: a small town (2x2 blocks) that builds and renders in a fraction of a second."""

from __future__ import annotations

import os
import random
import subprocess
import sys
import tempfile

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
# pytest -n 2 runs two workers on two cores: one thread each, or OpenMP spins and crawls
os.environ.setdefault("OMP_NUM_THREADS", "1")
# keep anything that might write caches inside a throwaway folder
os.environ.setdefault("MPLCONFIGDIR", tempfile.mkdtemp(prefix="vlocbench-mpl-"))

import numpy as np
import yaml

from vlocbench.bench.experiment import load_experiment
from vlocbench.bench.runner import run_experiment
from vlocbench.config import to_dict
from vlocbench.sim.camera import Camera, Extrinsics, Intrinsics
from vlocbench.sim.town import RouteSpec, TownSpec, generate_town


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--test-order",
        default="file",
        help="file (as collected), reverse, or shuffle:SEED: run the tests in another order, to "
        "find a test that passes only after another (shared fixtures hold state)",
    )


def pytest_configure(config: pytest.Config) -> None:
    # checked before collection, so a typo stops the run at once rather than after the imports
    order = config.getoption("--test-order")
    seed = order.removeprefix("shuffle:")
    if order not in ("file", "reverse") and not (order.startswith("shuffle:") and seed.isdigit()):
        raise pytest.UsageError(f"--test-order: {order!r}; valid: file, reverse, shuffle:SEED")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    order = config.getoption("--test-order")
    if order == "reverse":
        items.reverse()
    elif order.startswith("shuffle:"):
        # every xdist worker collects with the same seed, so they agree on the order
        random.Random(int(order.removeprefix("shuffle:"))).shuffle(items)


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
def _shared_sim(small_town):
    from vlocbench.sim import Simulator

    with Simulator(small_town) as sim:
        yield sim


@pytest.fixture
def small_sim(_shared_sim):
    """The session's simulator of the small town, by day with the default car: the tests that
    share it change its conditions and car, and the order they run in varies (``-n 2``)."""
    from vlocbench.sim import Conditions, VehicleParams

    _shared_sim.set_conditions(Conditions())
    _shared_sim.set_vehicle(VehicleParams())
    return _shared_sim


# -- a short real gallery of the small town (320x240), captured once per test session --------

# 4 samples a pixel: at this low resolution one sample moves the small map's few features enough
# to change single answers (the default sampling is tested in tests/sim/test_renderer.py)
CAMERA = Camera("right", Intrinsics(320, 240, 90.0), Extrinsics(), antialias=True)


@pytest.fixture(scope="session")
def stretch(small_town):
    """The first 60 m of the small town's route."""
    from vlocbench.bench.towns import plan_town_route
    from vlocbench.nav import WaypointPath

    path = plan_town_route(small_town)
    return WaypointPath(path.xy[:31])


@pytest.fixture(scope="session")
def gallery(small_town, stretch, tmp_path_factory):
    from vlocbench.bench.gallery_capture import capture_gallery
    from vlocbench.sim import Simulator

    with Simulator(small_town) as sim:
        return capture_gallery(sim, stretch, (CAMERA,), tmp_path_factory.mktemp("gallery"))


@pytest.fixture(scope="session")
def sift_map(gallery, tmp_path_factory):
    from vlocbench.loc.mapping import build_map
    from vlocbench.loc.registry import method_conf

    out = tmp_path_factory.mktemp("map") / "sift"
    report = build_map(gallery, method_conf("sift"), out)
    return out, report


def query_pose(stretch, index, forward_m=1.0, left_m=0.3, yaw_rad=0.02):
    """A pose between gallery places: off the driven line, turned a little."""
    yaw = float(stretch.yaw_rad[index])
    xy = stretch.xy[index] + forward_m * np.array([np.cos(yaw), np.sin(yaw)])
    xy += left_m * np.array([-np.sin(yaw), np.cos(yaw)])
    return float(xy[0]), float(xy[1]), yaw + yaw_rad


def last_line_in_a_process(code: str, **env: str) -> str:
    """The last line ``python -c code`` prints in a fresh process with ``env`` added."""
    run = subprocess.run(
        [sys.executable, "-c", code],
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    return run.stdout.strip().splitlines()[-1]


def call_behind_build_lock(folder, call, while_held=lambda: None, wait_s=1.0):
    """``call()`` in a thread while ``folder``'s build lock (:mod:`vlocbench.locks`) is held as
    another process building there holds it: the call must still wait after ``wait_s`` (and
    ``while_held()`` checks what it has not done); returns its result once the lock is let go."""
    import fcntl
    import threading

    from vlocbench.locks import LOCK_FILE

    folder.mkdir(parents=True, exist_ok=True)
    got: list = []
    with open(folder / LOCK_FILE, "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        waiting = threading.Thread(target=lambda: got.append(call()))
        waiting.start()
        waiting.join(timeout=wait_s)
        assert waiting.is_alive() and not got
        while_held()
    waiting.join()
    return got[0]


# -- a real experiment end to end: gallery, map, episodes, store (shared by the bench, ROS and CLI
# tests; the run takes about 20 s) ------------------------------------------------------------------
@pytest.fixture(scope="session")
def tiny(tmp_path_factory):
    root = tmp_path_factory.mktemp("tiny")
    (root / "small.yaml").write_text(yaml.safe_dump(to_dict(small_spec())))
    spec = {
        "name": "tiny",
        "towns": [str(root / "small.yaml")],
        "route_length_m": 60,
        "methods": ["sift"],
        "sweep": {"illumination.k": [0, 6]},
        "repetitions": 1,
        "baseline_repetitions": 1,  # one odometry drive: the suite stays fast
        "gallery": {"camera": {"intrinsics": {"width": 320, "height": 240}}},
        "output": str(root / "out"),
        "cache": str(root / "cache"),
    }
    (root / "tiny.yaml").write_text(yaml.safe_dump(spec))
    summary = run_experiment(load_experiment(root / "tiny.yaml"), progress=False)
    return root, summary


def assert_stops_cleanly(proc, stop: int, code: int) -> str:
    """Send ``stop`` to the subprocess ``proc`` (stderr piped, text): it exits with ``code`` and
    prints no native stack trace (glog's failure handler). Returns its stderr."""
    proc.send_signal(stop)
    try:
        _, err = proc.communicate(timeout=60)  # reads its pipes to the end and closes them
    except subprocess.TimeoutExpired:
        proc.kill()  # not left running after the test (it would hold its ROS domain or store)
        _, err = proc.communicate()
        pytest.fail(f"still running 60 s after signal {stop}, killed; its stderr:\n{err}")
    assert proc.returncode == code, err
    assert "Aborted" not in err and "stack trace" not in err, err
    return err
