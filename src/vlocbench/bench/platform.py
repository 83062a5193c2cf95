"""The platform an episode ran on, as far as its numbers depend on it: stored with every episode.

The same config and seed give the same numbers on one machine, to the last digit; on another they
need not. Its OpenGL driver draws a frame a little differently (:mod:`vlocbench.sim.fingerprint`),
numpy's, OpenCV's and the BLAS's kernels are chosen by the CPU, and so are PyTorch's (a fixed
convolution rounds otherwise through its AVX2 kernels than its AVX-512 ones, and a GPU's
otherwise again), and a closed-loop drive carries a
rounding's difference on into other answers and failures. So each worker process computes, once,
digests of fixed computations on each of them: episodes with the same :attr:`Platform.id` were
computed alike, and a store whose episodes have several is named as such in its report.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import json
import platform as _machine
from dataclasses import asdict, dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

PLATFORM_FILE = "platform.json"  # in a gallery's and a map's folder: what made it
# the distributions whose versions a result's numbers depend on ("" where one is not installed)
PACKAGES = (
    "mujoco",
    "pycolmap",
    "numpy",
    "opencv-contrib-python-headless",
    "scipy",
    "torch",
    "kornia",
)


@dataclass(frozen=True)
class Platform:
    """Digests of fixed computations (16 hex digits each) and what ran them.

    ``render``: the pixels of a fixed scene; ``numeric``: fixed numpy, BLAS and OpenCV results;
    ``torch``: a fixed forward pass on the learned methods' device (``auto``'s), "" where
    PyTorch is not installed or does not load (``details["torch_error"]`` then says why; the
    methods without a network run on); ``packages``: versions of :data:`PACKAGES`.
    ``details`` (not part of the identity): the GL driver, the CPU, Python, the torch device.
    """

    render: str
    numeric: str
    torch: str
    packages: dict[str, str]
    details: dict[str, str] = field(default_factory=dict, compare=False)

    @property
    def id(self) -> str:
        """The platform's identity: equal ids, equal numbers for equal configs and seeds."""
        identity = [self.render, self.numeric, self.torch, sorted(self.packages.items())]
        return hashlib.sha256(json.dumps(identity).encode()).hexdigest()[:12]

    def to_dict(self) -> dict[str, object]:
        """The record as stored: its id and every field."""
        return {"id": self.id, **asdict(self)}


def numeric_fingerprint() -> str:
    """A digest of fixed numpy (matrix product, transcendental functions, a sum), SVD and OpenCV
    (a blur, a resize) results: each dispatches to kernels the CPU's instruction set chooses."""
    import cv2

    a = np.random.default_rng(0).standard_normal((96, 96))
    image = (np.random.default_rng(1).random((64, 80)) * 255).astype(np.float32)
    values = (
        a @ a.T,
        np.exp(a),
        np.sin(a),
        np.arctan2(a, a.T),
        np.sum(a, axis=0),
        np.linalg.svd(a, compute_uv=False),
        cv2.GaussianBlur(image, (7, 7), 1.6),
        cv2.resize(image, (40, 32), interpolation=cv2.INTER_AREA),
    )
    digest = hashlib.sha256()
    for v in values:
        digest.update(np.ascontiguousarray(v, dtype=np.float64).tobytes())
    return digest.hexdigest()[:16]


def _version(package: str) -> str:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return ""


@functools.cache
def current_platform() -> Platform:
    """This process's platform, computed once (a few seconds: a small town drawn twice, PyTorch
    loaded where it is installed, so that every episode of a machine has the same record)."""
    from vlocbench.sim.fingerprint import render_fingerprint

    render = render_fingerprint()
    details = {
        "gl_renderer": render.gl_renderer,
        "gl_version": render.gl_version,
        "gl_backend": render.backend,
        "cpu": _cpu_name(),
        "python": _machine.python_version(),
    }
    torch = ""
    if importlib.util.find_spec("torch") is not None:
        from vlocbench.loc.learned import compute_fingerprint, resolve_device

        try:
            torch = compute_fingerprint()
            details["torch_device"] = resolve_device()
        except Exception as exc:  # a PyTorch that does not load stops its methods, not the rest
            details["torch_error"] = f"{type(exc).__name__}: {exc}"[:300]
    packages = {p: _version(p) for p in PACKAGES}
    return Platform(render.digest, numeric_fingerprint(), torch, packages, details)


def write_platform_file(folder: Path, gallery: Path | None = None) -> None:
    """Record in a gallery's or map's ``folder``, just made, the platform that made it (and, for a
    map, its gallery's record, from ``gallery``): the cache is keyed by what determines a
    gallery, not by the machine that drew it."""
    record: dict[str, Any] = {"made_on": current_platform().to_dict()}
    if gallery is not None:
        record["gallery"] = gallery.name
        record["gallery_made_on"] = read_platform_file(gallery).get("made_on")
    tmp = folder / (PLATFORM_FILE + ".tmp")
    tmp.write_text(json.dumps(record, indent=1))
    tmp.replace(folder / PLATFORM_FILE)


def read_platform_file(folder: Path) -> dict[str, Any]:
    """A gallery's or map's platform record ({} where it has none: made before they were
    recorded, or the process was killed between the two files)."""
    try:
        return dict(json.loads((folder / PLATFORM_FILE).read_text()))
    except (OSError, ValueError):
        return {}


def _cpu_name() -> str:
    """The CPU's model name and its widest vector instructions (Linux: two machines both called
    "AMD EPYC" may differ in those, and so in their kernels' rounding), else what the platform
    module gives."""
    name, flags = "", set[str]()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                if key.strip() == "model name" and not name:
                    name = value.strip()
                elif key.strip() == "flags" and not flags:
                    flags = set(value.split())
    except OSError:
        pass
    name = name or _machine.processor() or _machine.machine()
    vector = vector_extension(flags)
    return f"{name}, {vector}" if vector else name


def vector_extension(flags: set[str]) -> str:
    """The widest x86 vector extension among a CPU's ``flags`` (as /proc/cpuinfo lists them),
    which numpy's, OpenBLAS's and PyTorch's kernels dispatch on; "" where none is listed."""
    for flag, name in (
        ("avx512f", "AVX-512"),
        ("avx2", "AVX2"),
        ("avx", "AVX"),
        ("sse4_2", "SSE4.2"),
    ):
        if flag in flags:
            return name
    return ""
