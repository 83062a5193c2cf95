"""The platform record: its identity, and digests that follow the machine's kernels."""

import dataclasses
import platform

import numpy as np
import pytest

from tests.conftest import last_line_in_a_process
from vlocbench.bench.platform import (
    Platform,
    current_platform,
    numeric_fingerprint,
    vector_extension,
)
from vlocbench.sim.fingerprint import render_fingerprint


def test_the_identity_is_the_digests_and_versions_not_the_description():
    a = Platform("r" * 16, "n" * 16, "", {"mujoco": "4.0.1"}, {"cpu": "x"})
    assert a.id == dataclasses.replace(a, details={"cpu": "y"}).id
    for change in ({"render": "s" * 16}, {"numeric": "m" * 16}, {"torch": "t" * 16}):
        assert dataclasses.replace(a, **change).id != a.id
    assert dataclasses.replace(a, packages={"mujoco": "4.0.2"}).id != a.id
    here = current_platform()
    assert here.to_dict()["id"] == here.id and here.render and here.numeric
    assert here.packages["numpy"] == np.__version__ and here.details["gl_renderer"]


def test_the_cpu_is_named_with_its_widest_vector_extension():
    """Two machines both called "AMD EPYC" rounded otherwise (AVX-512 kernels against AVX2):
    the record says which."""
    assert vector_extension({"fpu", "sse4_2", "avx", "avx2", "avx512f", "avx512bw"}) == "AVX-512"
    assert vector_extension({"sse4_2", "avx", "avx2", "fma"}) == "AVX2"
    assert vector_extension({"neon", "asimd"}) == ""
    if platform.system() == "Linux" and platform.machine() == "x86_64":
        cpu = current_platform().details["cpu"]
        assert cpu.rpartition(", ")[2] in ("AVX-512", "AVX2", "AVX", "SSE4.2"), cpu


def _numeric_in_a_process(**env):
    code = "from vlocbench.bench.platform import numeric_fingerprint; print(numeric_fingerprint())"
    return last_line_in_a_process(code, **env)


def test_the_numeric_digest_follows_the_blas_kernels_not_the_threads():
    here = numeric_fingerprint()
    assert _numeric_in_a_process(OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1") == here
    blas = np.show_config(mode="dicts")["Build Dependencies"]["blas"]["name"]
    if "openblas" not in blas or platform.machine() != "x86_64":
        pytest.skip(f"OpenBLAS's x86-64 kernels are the other ones tried; numpy uses {blas}")
    # the oldest x86-64 kernels (SSE3) round a matrix product otherwise than a newer CPU's
    assert _numeric_in_a_process(OPENBLAS_CORETYPE="Prescott") != here


def test_a_pytorch_that_does_not_load_leaves_the_platform_without_it(monkeypatch):
    import vlocbench.loc.learned as learned

    def broken(device="auto"):
        raise OSError("libtorch_cpu.so: cannot open shared object file")

    monkeypatch.setattr(learned, "compute_fingerprint", broken)
    current_platform.cache_clear()
    try:
        p = current_platform()
    finally:  # the next test's platform is computed again, with PyTorch as it is
        current_platform.cache_clear()
    assert p.torch == "" and "cannot open shared object" in p.details["torch_error"]
    assert p.render == render_fingerprint().digest
