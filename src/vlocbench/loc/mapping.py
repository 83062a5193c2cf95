"""Maps: a gallery's features, matches and 3D points triangulated from its known camera poses.

``build_map`` runs the stages hloc-style, each cached in the map folder and recomputed only when
missing (or with ``overwrite``):

    features.h5   local features per gallery image (keyed by image name)
    global.h5     global descriptors per image, retrieval.npz what the descriptor learned
    pairs.txt     mapping pairs: the top retrievals (default) or the nearest gallery poses
    matches.h5    matches per pair, filtered by the epipolar geometry of the known poses
    database.db, sfm/   the COLMAP database and model (pycolmap ``triangulate_points``)
    map.json      method, gallery, statistics, stage times (what each did, on how many workers);
                  written last, so a folder with it holds a finished map, which ``build_map``
                  returns as it is

One process builds a map folder at a time (:func:`vlocbench.locks.building`); another that asks for
the same map waits, then finds it finished. A map is keyed by (gallery, what builds it: the
method's stages and the mapping settings, not the method's name): :func:`default_map_dir` names
its folder so.
"""

from __future__ import annotations

import json
import re
import shutil
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Executor, Future
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from itertools import islice
from pathlib import Path
from typing import Any, Literal, TypeVar

import h5py
import numpy as np

from vlocbench.config import ADDED_OPTION, config_hash, hashed_values, require, require_one_of
from vlocbench.errors import LocalizationError
from vlocbench.geometry import invert_pose
from vlocbench.loc.features import FeatureExtractor, Features
from vlocbench.loc.gallery import CameraModel, Gallery, GalleryWriter
from vlocbench.loc.matchers import Matcher, match_pairs
from vlocbench.loc.native import pycolmap, quiet_pycolmap
from vlocbench.loc.registry import (
    MethodConf,
    build_features,
    build_matcher,
    build_retrieval,
    matcher_class,
    stage_params,
)
from vlocbench.loc.retrieval import nearest_poses, top_k
from vlocbench.locks import building

MAP_FILE = "map.json"
MATCH_CHUNK = 64  # pairs matched between writes to the cache (what a kill can lose)
EXTRACT_CHUNK = 8  # images a job extracts (here, or in a pool process)
Progress = Callable[[str, int, int], None]  # stage, done, total


@dataclass(frozen=True)
class MappingConfig:
    """How a gallery's images are paired, and which matches triangulation takes.

    ``pairs="retrieval"`` (the paper's ``SfM_from_camera_poses.py``): each image with its
    ``num_pairs`` most similar gallery images by the global descriptor, itself among them (so 24
    others at 25); ``"poses"`` (vlocbench's option; the default of pose-prior methods, which have
    no descriptor): the ``num_pairs`` nearest other cameras. ``verification="epipolar"`` (hloc's
    ``geometric_verification`` with the known poses): a match is kept when each keypoint lies within
    ``epipolar_max_px`` of the other's epipolar line; ``"sampson"`` (vlocbench's option): the
    Sampson distance, which pools both images' errors, within ``epipolar_max_px``.
    ``min_track_length``: the fewest images a triangulated point must be seen in to stay in the
    map. 2 (COLMAP's and hloc's) keeps every point; 3 (vlocbench's option) drops the points seen
    in two images only, whose depth no third view checks: a false match that passes the epipolar
    check (e.g. between look-alike places that retrieval paired) lies off every surface.
    """

    pairs: Literal["retrieval", "poses"] = "retrieval"
    num_pairs: int = 25
    verification: Literal["epipolar", "sampson"] = "epipolar"
    epipolar_max_px: float = 4.0
    min_triangulation_angle_deg: float = 1.5
    min_track_length: int = field(default=2, metadata=ADDED_OPTION)

    def __post_init__(self) -> None:
        require_one_of(self.pairs, ("retrieval", "poses"), "mapping.pairs")
        require_one_of(self.verification, ("epipolar", "sampson"), "mapping.verification")
        require(self.num_pairs >= 1, "mapping.num_pairs", "must be >= 1")
        require(self.epipolar_max_px > 0, "mapping.epipolar_max_px", "must be > 0")
        require(self.min_track_length >= 2, "mapping.min_track_length", "must be >= 2 (two views)")


@dataclass(frozen=True)
class MapReport:
    images: int
    pairs: int
    points: int
    mean_track_length: float
    mean_reprojection_error_px: float
    seconds: dict[str, float] = field(default_factory=dict)  # wall time per stage of this build
    # what this build's timed stages did (a resumed build does the rest): images whose features it
    # extracted ("features"), pairs it matched ("matching")
    done: dict[str, int] = field(default_factory=dict)
    workers: int = 1  # processes that extracted and matched (a pool's, else this one)


def map_name(conf: MethodConf, mapping: MappingConfig) -> str:
    """``FEATURES-HASH``: a map's folder name, its local features (a plugin's dotted path made a
    plain name) and the hash of what builds it: the method's stages with their presets'
    arguments and the mapping settings. Methods that differ only in how they localize share it."""
    features = re.sub(r"[^A-Za-z0-9_-]+", "_", conf.features).strip("_")
    return f"{features}-{config_hash((conf, mapping, stage_params(conf)), 8)}"


def default_map_dir(
    root: str | Path, gallery: Gallery, conf: MethodConf, mapping: MappingConfig
) -> Path:
    """``root/GALLERY-ID/FEATURES-HASH``: one folder per (gallery, map configuration)."""
    return Path(root) / gallery.identity / map_name(conf, mapping)


def build_seconds(
    maps_root: str | Path, name: str, images: int, folder: Path | None
) -> float | None:
    """A worker's seconds to build a map ``name`` (:func:`map_name`) of a gallery of ``images``
    images, from the finished maps of that name in ``maps_root`` (as :func:`default_map_dir` lays
    them out): their median seconds a worker per image extracted, per pair matched (and pairs per
    image), and per image for the rest (global descriptors, triangulation). What ``folder`` (the
    map's own, unfinished) already holds is not counted again. None: no finished map to go by.
    Reads its caches without the build's lock (a build may be writing them)."""
    rates: dict[str, list[float]] = {}
    for path in sorted(Path(maps_root).glob(f"*/{name}/{MAP_FILE}")):
        for key, rate in _build_rates(path).items():
            rates.setdefault(key, []).append(rate)
    if len(rates) < 4:
        return None
    extract, match, pairs_per_image, rest = (
        float(np.median(rates[k])) for k in ("features", "matching", "pairs", "rest")
    )
    listed = folder / "pairs.txt" if folder else None  # written once the pairs are chosen
    pairs = (
        len(listed.read_text().splitlines())
        if listed and listed.is_file()
        else round(images * pairs_per_image)
    )
    extracted = _entries(folder / "features.h5") if folder else 0
    matched = _entries(folder / "matches.h5") if folder else 0
    return extract * max(images - extracted, 0) + match * max(pairs - matched, 0) + rest * images


def _build_rates(path: Path) -> dict[str, float]:
    """A finished map's seconds a worker per unit of each stage (``features``: an image extracted,
    ``matching``: a pair matched, ``rest``: an image), and its ``pairs`` per image. A map whose
    report predates ``done`` counts the whole gallery and pairs as done, on one worker."""
    try:
        report = json.loads(path.read_text())["report"]
        seconds, images, pairs = report["seconds"], report["images"], report["pairs"]
    except (OSError, ValueError, KeyError):
        return {}
    done = report.get("done") or {"features": images, "matching": pairs}
    workers = report.get("workers", 1)
    rates = {"pairs": pairs / images} if images else {}
    for stage in ("features", "matching"):
        if done.get(stage):
            rates[stage] = seconds[stage] * workers / done[stage]
    if images:
        rates["rest"] = (seconds.get("global", 0.0) + seconds.get("triangulation", 0.0)) / images
    return rates


def _entries(path: Path) -> int:
    """Entries of an HDF5 cache that a build may be writing (0: none, or unreadable now)."""
    try:
        with h5py.File(path, "r", locking=False) as f:
            return len(f.keys())
    except OSError:
        return 0


# -- HDF5 caches ---------------------------------------------------------------------------------
def _writable_cache(path: Path) -> h5py.File:
    """A cache file to add to. One that a killed build left unreadable starts over: it is only a
    cache, and a rerun must finish what the kill interrupted."""
    try:
        return h5py.File(path, "a")
    except OSError:
        path.unlink(missing_ok=True)
        return h5py.File(path, "a")


class FeatureStore:
    """Features per image name in an HDF5 file."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def _open(self, mode: str) -> h5py.File:
        try:
            return h5py.File(self.path, mode)
        except OSError as exc:
            raise LocalizationError(
                f"{self.path} is corrupt ({exc}); delete it or rebuild with overwrite"
            ) from None

    def names(self) -> set[str]:
        if not self.path.exists():
            return set()
        with self._open("r") as f:
            return set(f.keys())

    def write(self, items: Iterator[tuple[str, Features]]) -> None:
        with _writable_cache(self.path) as f:
            for name, feats in items:
                if name in f:
                    del f[name]
                g = f.create_group(name)
                g["keypoints"], g["descriptors"], g["scores"] = (
                    feats.keypoints,
                    feats.descriptors,
                    feats.scores,
                )
                f.flush()

    @contextmanager
    def reading(self) -> Iterator[Callable[[str], Features]]:
        """Open the file once for many reads: ``with store.reading() as read: read(name)``."""
        with self._open("r") as f:
            yield lambda name: self._get(f, name)

    def _get(self, f: h5py.File, name: str) -> Features:
        try:
            g = f[name]
            return Features(g["keypoints"][()], g["descriptors"][()], g["scores"][()])
        except KeyError:
            raise LocalizationError(f"{self.path} has no features for {name!r}") from None


def _pair_key(a: str, b: str) -> str:
    return f"{a}|{b}".replace("/", "\\")


# -- geometry ------------------------------------------------------------------------------------
def fundamental_from_poses(
    cam_a: CameraModel, pose_a: np.ndarray, cam_b: CameraModel, pose_b: np.ndarray
) -> np.ndarray:
    """F with x_b^T F x_a = 0 for OpenCV pixel coordinates, from world_from_cam poses."""
    b_from_a = invert_pose(pose_b) @ pose_a
    R, t = b_from_a[:3, :3], b_from_a[:3, 3]
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    return np.linalg.inv(cam_b.K).T @ tx @ R @ np.linalg.inv(cam_a.K)


def _epipolar_terms(F: np.ndarray, xa: np.ndarray, xb: np.ndarray) -> tuple[np.ndarray, ...]:
    """x_b^T F x_a, and the epipolar lines F x_a (in b) and F^T x_b (in a), each (M, 3)."""
    ha = np.hstack([xa, np.ones((len(xa), 1))])
    hb = np.hstack([xb, np.ones((len(xb), 1))])
    Fa, Ftb = ha @ F.T, hb @ F
    return np.einsum("ij,ij->i", hb, Fa), Fa, Ftb


def sampson_px(F: np.ndarray, xa: np.ndarray, xb: np.ndarray) -> np.ndarray:
    """Sampson distance (px) of correspondences (M, 2) under F."""
    residual, Fa, Ftb = _epipolar_terms(F, xa, xb)
    den = Fa[:, 0] ** 2 + Fa[:, 1] ** 2 + Ftb[:, 0] ** 2 + Ftb[:, 1] ** 2
    return np.abs(residual) / np.sqrt(np.maximum(den, 1e-12))


def epipolar_line_px(F: np.ndarray, xa: np.ndarray, xb: np.ndarray) -> np.ndarray:
    """(M, 2): the distance (px) of each x_a from x_b's epipolar line in a, and of x_b from x_a's
    in b (hloc's ``compute_epipolar_errors``, in pixels of square-pixel cameras)."""
    residual, Fa, Ftb = _epipolar_terms(F, xa, xb)
    lines = np.stack([np.hypot(Ftb[:, 0], Ftb[:, 1]), np.hypot(Fa[:, 0], Fa[:, 1])], 1)
    return np.abs(residual)[:, None] / np.maximum(lines, 1e-12)


def verified(mapping: MappingConfig, F: np.ndarray, xa: np.ndarray, xb: np.ndarray) -> np.ndarray:
    """(M,) bool: the matches (x_a, x_b) that agree with F under ``mapping.verification``."""
    if mapping.verification == "sampson":
        return sampson_px(F, xa, xb) < mapping.epipolar_max_px
    return np.all(epipolar_line_px(F, xa, xb) <= mapping.epipolar_max_px, axis=1)


def colmap_camera(cam: CameraModel, camera_id: int) -> pycolmap.Camera:
    """COLMAP's pixel centres sit at +0.5: the principal point moves by half a pixel."""
    K = cam.K
    return pycolmap.Camera(
        model="PINHOLE",
        width=cam.width,
        height=cam.height,
        camera_id=camera_id,
        params=[K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5],
    )


def rigid_of(a_from_b: np.ndarray) -> pycolmap.Rigid3d:
    """pycolmap's transform of a (4, 4) pose."""
    return pycolmap.Rigid3d(a_from_b[:3, :4])


def pose_of(rigid: pycolmap.Rigid3d) -> np.ndarray:
    """The (4, 4) pose of a pycolmap transform."""
    return np.vstack([rigid.matrix(), [0.0, 0.0, 0.0, 1.0]])


# -- the pipeline --------------------------------------------------------------------------------
def _extract(
    gallery: Gallery,
    conf: MethodConf,
    store: FeatureStore,
    overwrite: bool,
    progress: Progress | None,
    pool: MatchPool | None = None,
) -> int:
    """Each gallery image's features into ``store``, ``EXTRACT_CHUNK`` images a job: here, or in
    ``pool``'s processes (a learned extractor runs on one thread in any process: the same
    features); returns how many images it extracted (those the store lacked)."""
    try:
        done = set() if overwrite else store.names()
    except LocalizationError:  # left unreadable by a killed build: extract again
        store.path.unlink()
        done = set()
    todo = [n for n in gallery.names if n not in done]
    if not todo:
        return 0
    chunks = [todo[start : start + EXTRACT_CHUNK] for start in range(0, len(todo), EXTRACT_CHUNK)]
    extractor = build_features(conf.features) if pool is None else None
    jobs = ((conf.features, gallery, chunk, extractor) for chunk in chunks)

    def items() -> Iterator[tuple[str, Features]]:
        count = 0
        for (_, _, names, _), feats in _in_order(_extract_chunk, jobs, pool):
            for name, f in zip(names, feats, strict=True):
                count += 1
                yield name, f
                if progress:
                    progress("features", count, len(todo))

    store.write(items())
    return len(todo)


def _global(
    gallery: Gallery, conf: MethodConf, out: Path, features: FeatureStore, overwrite: bool
) -> np.ndarray | None:
    """(N, D) global descriptors of the gallery, or None for pose-prior retrieval."""
    descriptor = build_retrieval(conf.retrieval)
    if descriptor is None:
        return None
    state_path, store_path = out / "retrieval.npz", out / "global.h5"
    if overwrite or not state_path.exists():
        with features.reading() as read:
            descriptor.fit([read(n) for n in gallery.names])
        # numpy's stub reads the arrays as its allow_pickle flag
        np.savez(state_path, **descriptor.state())  # type: ignore[arg-type]
        store_path.unlink(missing_ok=True)
    else:
        with np.load(state_path) as state:
            descriptor.load_state(dict(state))
    with _writable_cache(store_path) as f, features.reading() as read:
        for name in gallery.names:
            if name not in f:
                f[name] = descriptor.describe(gallery.load_image(name), read(name))
                f.flush()
        return np.stack([f[n][()] for n in gallery.names])


def _pairs(
    gallery: Gallery, mapping: MappingConfig, descriptors: np.ndarray | None
) -> list[tuple[str, str]]:
    poses = np.stack([im.world_from_cam for im in gallery.images])
    seen: set[tuple[int, int]] = set()
    for i in range(len(gallery)):
        if mapping.pairs == "retrieval" and descriptors is not None:
            near = top_k(descriptors[i], descriptors, mapping.num_pairs)  # itself among them
        else:
            near = nearest_poses(poses, poses[i], mapping.num_pairs + 1)
        seen |= {(min(i, j), max(i, j)) for j in near if j != i}
    names = gallery.names
    return [(names[i], names[j]) for i, j in sorted(seen)]


def pools_matching(conf: MethodConf) -> bool:
    """Whether a :class:`MatchPool` builds this method's map (its features and its matches): a
    network matcher (``match_many``), whose passes run on one thread in any process (the same
    matches), and slowly, as its learned extractor's; the nearest-neighbour matchers are fast,
    and their matrix products follow BLAS's threads."""
    return hasattr(matcher_class(conf.matcher), "match_many")


@dataclass(frozen=True)
class MatchPool:
    """Processes to extract a map's images' features and match its pairs in (``workers`` of them,
    e.g. a ProcessPoolExecutor's)."""

    executor: Executor
    workers: int


FeaturePairs = list[tuple[Features, Features]]
_EXTRACTORS: dict[str, FeatureExtractor] = {}  # per pool process: each network loaded once
_MATCHERS: dict[str, Matcher] = {}
Job = TypeVar("Job", bound=tuple[Any, ...])
Result = TypeVar("Result")
Net = TypeVar("Net")


def _loaded(cache: dict[str, Net], name: str, build: Callable[[str], Net]) -> Net:
    if name not in cache:
        cache[name] = build(name)
    return cache[name]


def _extract_chunk(
    preset: str, gallery: Gallery, names: list[str], extractor: FeatureExtractor | None
) -> list[Features]:
    """The features of a chunk of gallery images, by ``extractor`` (the driver's) or, in a pool
    process, by its own."""
    if extractor is None:
        extractor = _loaded(_EXTRACTORS, preset, build_features)
    return [extractor.extract(gallery.load_image(name)) for name in names]


def _match_chunk(name: str, feats: FeaturePairs, matcher: Matcher | None) -> list[np.ndarray]:
    """The matches of a chunk of pairs, by ``matcher`` (the driver's) or, in a pool process, by
    its own (each pair on one thread either way, so the same matches)."""
    if matcher is None:
        matcher = _loaded(_MATCHERS, name, build_matcher)
    return match_pairs(matcher, feats)


def _in_order(
    run: Callable[..., Result], jobs: Iterable[Job], pool: MatchPool | None
) -> Iterator[tuple[Job, Result]]:
    """``(job, run(*job))`` for each of ``jobs`` in their order: here, or in ``pool``'s processes
    with two jobs a worker in flight ahead of the one taken (every worker kept busy while the
    caller writes)."""
    if pool is None:
        yield from ((job, run(*job)) for job in jobs)
        return
    pending = iter(jobs)
    ahead: deque[tuple[Job, Future[Result]]] = deque()
    for job in islice(pending, 2 * pool.workers):
        ahead.append((job, pool.executor.submit(run, *job)))
    while ahead:
        job, future = ahead.popleft()
        result = future.result()
        for later in islice(pending, 1):
            ahead.append((later, pool.executor.submit(run, *later)))
        yield job, result


def _match(
    gallery: Gallery,
    conf: MethodConf,
    mapping: MappingConfig,
    features: FeatureStore,
    pairs: list[tuple[str, str]],
    path: Path,
    progress: Progress | None,
    pool: MatchPool | None = None,
) -> tuple[dict[tuple[str, str], np.ndarray], int]:
    """Matches of each pair that agree with the known poses, cached in ``path`` a chunk of
    ``MATCH_CHUNK`` pairs at a time (a batched matcher gets a chunk at once): here, or in
    ``pool``'s processes; and how many pairs it matched (those the cache lacked)."""
    with _writable_cache(path) as f, features.reading() as read:
        todo = [(a, b) for a, b in pairs if _pair_key(a, b) not in f]
        chunks = [todo[start : start + MATCH_CHUNK] for start in range(0, len(todo), MATCH_CHUNK)]
        matcher = build_matcher(conf.matcher) if todo and pool is None else None
        jobs = ((conf.matcher, [(read(a), read(b)) for a, b in c], matcher) for c in chunks)
        for k, (chunk, ((_, feats, _), found)) in enumerate(
            zip(chunks, _in_order(_match_chunk, jobs, pool), strict=True)
        ):
            for (a, b), (fa, fb), m in zip(chunk, feats, found, strict=True):
                if len(m):
                    ia, ib = (
                        gallery.images[gallery.index_of(a)],
                        gallery.images[gallery.index_of(b)],
                    )
                    F = fundamental_from_poses(
                        gallery.cameras[ia.camera],
                        ia.world_from_cam,
                        gallery.cameras[ib.camera],
                        ib.world_from_cam,
                    )
                    m = m[verified(mapping, F, fa.keypoints[m[:, 0]], fb.keypoints[m[:, 1]])]
                f[_pair_key(a, b)] = m.astype(np.uint32).reshape(-1, 2)
            f.flush()  # unflushed, a kill leaves the file unreadable and every match is lost
            if progress:
                done = len(pairs) - len(todo) + k * MATCH_CHUNK + len(chunk)
                progress("matches", done, len(pairs))
        return {(a, b): f[_pair_key(a, b)][()] for a, b in pairs}, len(todo)


def posed_model(gallery: Gallery) -> pycolmap.Reconstruction:
    """The gallery as a COLMAP model with known poses and no points: camera k + 1 is the
    gallery's k-th camera (PINHOLE, COLMAP's pixel centres), image k + 1 its k-th image. What
    hloc's triangulation (``triangulation.main(reference_model=...)``) starts from."""
    rec = pycolmap.Reconstruction()
    cam_ids = {name: k + 1 for k, name in enumerate(gallery.cameras)}
    for name, cam in gallery.cameras.items():
        rec.add_camera_with_trivial_rig(colmap_camera(cam, cam_ids[name]))
    for k, im in enumerate(gallery.images):
        image = pycolmap.Image(name=im.name, camera_id=cam_ids[im.camera], image_id=k + 1)
        rec.add_image_with_trivial_frame(image, rigid_of(invert_pose(im.world_from_cam)))
    return rec


def _identity(gallery: Gallery, conf: MethodConf, mapping: MappingConfig) -> dict[str, Any]:
    """What a map's cached stages depend on, as its ``map.json`` keeps it (JSON types)."""
    return json.loads(
        json.dumps(
            {
                "gallery_identity": gallery.identity,
                "method": asdict(conf),
                "mapping": hashed_values(mapping),  # an added option at its default is left out
                "stages": stage_params(conf),
            }
        )
    )


def _finished_map(out: Path, identity: dict[str, Any]) -> MapReport | None:
    """The report of the map finished in ``out``, if it is this one (None: not finished, or
    finished before its report was kept). A folder that holds a finished map of something else is
    refused: its cached stages would be mixed into this one. (Maps built before ``stages`` was
    kept are checked without.)"""
    try:
        built = json.loads((out / MAP_FILE).read_text())
    except FileNotFoundError:
        return None
    except json.JSONDecodeError as exc:
        raise LocalizationError(f"{out / MAP_FILE} is corrupt: {exc!r}") from None
    differ = [k for k, v in identity.items() if k in built and built[k] != v]
    if differ:
        raise LocalizationError(
            f"{out} holds a map built with another {', '.join(differ)} ({built.get('method')}); "
            "build in another folder, or pass overwrite (--overwrite) to rebuild it"
        )
    return MapReport(**built["report"]) if "report" in built else None


def map_info(map_dir: str | Path) -> tuple[MethodConf, Path]:
    """(method, gallery folder) a map was built with, from its ``map.json``."""
    path = Path(map_dir) / MAP_FILE
    if not path.is_file():
        raise LocalizationError(f"{map_dir} is not a map: {MAP_FILE} is missing")
    try:
        info = json.loads(path.read_text())
        return MethodConf(**info["method"]), Path(info["gallery"])
    except (json.JSONDecodeError, KeyError, TypeError) as exc:
        raise LocalizationError(f"{path} is corrupt: {exc!r}") from None


COLMAP_PINHOLES = ("PINHOLE", "SIMPLE_PINHOLE")  # the camera models a gallery can take


def export_colmap(gallery: Gallery, out_dir: str | Path) -> Path:
    """Write :func:`posed_model` as a COLMAP text model (cameras.txt, images.txt with empty point
    lines, points3D.txt) in ``out_dir``; the images stay in ``gallery.root / "images"``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    posed_model(gallery).write_text(out)
    return out


def import_colmap(model_dir: str | Path, image_dir: str | Path, out_dir: str | Path) -> Gallery:
    """A gallery in ``out_dir`` from a COLMAP model (text or binary) and its images: every
    registered image at its pose, copied as it is. Cameras must be undistorted pinholes
    (PINHOLE or SIMPLE_PINHOLE; COLMAP's ``image_undistorter`` makes them so)."""
    model_dir, image_dir = Path(model_dir), Path(image_dir)
    try:
        rec = pycolmap.Reconstruction(model_dir)
    except Exception as exc:  # pycolmap raises bare ValueError/RuntimeError on bad folders
        raise LocalizationError(f"{model_dir} is not a COLMAP model: {exc}") from None
    cameras: dict[int, CameraModel] = {}
    for cam_id, cam in rec.cameras.items():
        model = cam.model.name
        if model not in COLMAP_PINHOLES:
            raise LocalizationError(
                f"{model_dir}: camera {cam_id} is {model}; a gallery takes "
                f"{', '.join(COLMAP_PINHOLES)} (undistort the images first)"
            )
        fx, fy, cx, cy = (
            (cam.params[0], cam.params[0], *cam.params[1:3])
            if model == "SIMPLE_PINHOLE"
            else tuple(cam.params)
        )
        K = np.array([[fx, 0, cx - 0.5], [0, fy, cy - 0.5], [0, 0, 1]])  # OpenCV's pixel centres
        cameras[cam_id] = CameraModel(int(cam.width), int(cam.height), K)
    writer = GalleryWriter(out_dir)
    for _, image in sorted(rec.images.items()):
        if not image.has_pose:
            continue
        source = image_dir / image.name
        if not source.is_file():
            raise LocalizationError(f"{model_dir}: image {image.name!r} is not in {image_dir}")
        writer.add_file(
            image.name,
            source,
            f"camera{image.camera_id}",
            cameras[image.camera_id],
            invert_pose(pose_of(image.cam_from_world())),
        )
    if not writer.images:
        raise LocalizationError(f"{model_dir} has no registered images")
    return writer.close()


def _triangulate(
    gallery: Gallery,
    mapping: MappingConfig,
    features: FeatureStore,
    matches: dict[tuple[str, str], np.ndarray],
    out: Path,
) -> pycolmap.Reconstruction:
    rec = posed_model(gallery)
    ids = {image.name: image_id for image_id, image in sorted(rec.images.items())}
    db_path = out / "database.db"
    db_path.unlink(missing_ok=True)
    db = pycolmap.Database.open(db_path)
    for _, camera in sorted(rec.cameras.items()):
        db.write_camera(camera, use_camera_id=True)
    for rig in rec.rigs.values():
        db.write_rig(rig, use_rig_id=True)
    for frame in rec.frames.values():
        db.write_frame(frame, use_frame_id=True)
    with features.reading() as read:
        for name, image_id in ids.items():
            db.write_image(rec.images[image_id], use_image_id=True)
            db.write_keypoints(image_id, read(name).keypoints.astype(np.float32) + 0.5)
    for (a, b), m in matches.items():
        if len(m):
            db.write_matches(ids[a], ids[b], m)
            geometry = pycolmap.TwoViewGeometry()
            geometry.inlier_matches = m
            geometry.config = pycolmap.TwoViewGeometryConfiguration.CALIBRATED
            db.write_two_view_geometry(ids[a], ids[b], geometry)
    db.close()
    options = pycolmap.IncrementalPipelineOptions()
    options.triangulation.min_angle = mapping.min_triangulation_angle_deg
    sfm = out / "sfm"
    shutil.rmtree(sfm, ignore_errors=True)
    sfm.mkdir()
    return pycolmap.triangulate_points(rec, db_path, gallery.root / "images", sfm, options=options)


def build_map(
    gallery: Gallery,
    conf: MethodConf,
    out_dir: str | Path,
    mapping: MappingConfig | None = None,
    overwrite: bool = False,
    progress: Progress | None = None,
    pool: MatchPool | None = None,
) -> MapReport:
    """Build (or finish building) the map of ``gallery`` with method ``conf`` in ``out_dir``; a
    finished one is returned as it is (its report is the build's). ``pool``: processes that match
    the pairs where :func:`pools_matching` (the matcher's time spread over cores; the same
    matches)."""
    mapping = mapping or MappingConfig()
    pool = pool if pool and pools_matching(conf) else None
    out = Path(out_dir)
    identity = _identity(gallery, conf, mapping)
    with building(out, "a map"):
        finished = None if overwrite else _finished_map(out, identity)
        return finished or _build(gallery, conf, out, mapping, identity, overwrite, progress, pool)


def _build(
    gallery: Gallery,
    conf: MethodConf,
    out: Path,
    mapping: MappingConfig,
    identity: dict[str, Any],
    overwrite: bool,
    progress: Progress | None,
    pool: MatchPool | None,
) -> MapReport:
    quiet_pycolmap()
    seconds = {}
    t = time.perf_counter()
    features = FeatureStore(out / "features.h5")
    done = {"features": _extract(gallery, conf, features, overwrite, progress, pool)}
    seconds["features"] = time.perf_counter() - t
    t = time.perf_counter()
    descriptors = _global(gallery, conf, out, features, overwrite)
    seconds["global"] = time.perf_counter() - t
    t = time.perf_counter()
    pairs = _pairs(gallery, mapping, descriptors)
    (out / "pairs.txt").write_text("".join(f"{a} {b}\n" for a, b in pairs))
    if overwrite:
        (out / "matches.h5").unlink(missing_ok=True)
    matches, done["matching"] = _match(
        gallery, conf, mapping, features, pairs, out / "matches.h5", progress, pool
    )
    seconds["matching"] = time.perf_counter() - t
    t = time.perf_counter()
    rec = _triangulate(gallery, mapping, features, matches, out)
    if mapping.min_track_length > 2:
        short = [i for i, p in rec.points3D.items() if p.track.length() < mapping.min_track_length]
        for point_id in short:
            rec.delete_point3D(point_id)
        rec.write(out / "sfm")
    seconds["triangulation"] = time.perf_counter() - t
    report = MapReport(
        images=len(gallery),
        pairs=len(pairs),
        points=rec.num_points3D(),
        mean_track_length=float(rec.compute_mean_track_length()) if rec.num_points3D() else 0.0,
        mean_reprojection_error_px=float(rec.compute_mean_reprojection_error()),
        seconds=seconds,
        done=done,
        workers=pool.workers if pool else 1,
    )
    info = {
        "version": 1,
        "gallery": str(gallery.root.resolve()),
        **identity,
        "report": asdict(report),
    }
    tmp = out / (MAP_FILE + ".tmp")
    tmp.write_text(json.dumps(info, indent=1))
    tmp.replace(out / MAP_FILE)
    return report
