"""The suite's ``--test-order`` option (tests/conftest.py), in a pytest of its own."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FILES = ["tests/test_config.py", "tests/test_errors.py", "tests/test_geometry.py"]
# one process, no cache written: the order is the collection's alone
PYTEST = [
    sys.executable,
    "-m",
    "pytest",
    "--collect-only",
    "-q",
    "-p",
    "no:xdist",
    "-p",
    "no:cacheprovider",
]


def _collect(*options: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*PYTEST, *FILES, *options],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )


def _ids(done: subprocess.CompletedProcess[str]) -> list[str]:
    assert done.returncode == 0, done.stdout + done.stderr
    return [line for line in done.stdout.splitlines() if "::" in line]


def test_the_tests_run_reversed_or_shuffled_by_a_seed():
    as_collected = _ids(_collect())
    assert len(as_collected) >= 4
    assert _ids(_collect("--test-order", "reverse")) == as_collected[::-1]
    shuffled = _ids(_collect("--test-order", "shuffle:7"))
    assert sorted(shuffled) == sorted(as_collected) and shuffled != as_collected
    assert _ids(_collect("--test-order", "shuffle:7")) == shuffled


def test_an_unknown_order_is_a_usage_error_naming_the_valid_ones():
    for bad in ("backwards", "shuffle:", "shuffle:x"):
        done = _collect("--test-order", bad)
        assert done.returncode == 4, done.stdout + done.stderr  # pytest's usage error
        assert f"--test-order: {bad!r}; valid: file, reverse, shuffle:SEED" in done.stderr
