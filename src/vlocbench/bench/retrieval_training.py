"""Training a place descriptor for changed conditions (``vlocbench train-retrieval``): the NetVLAD
head of :mod:`vlocbench.loc.netvlad` over frozen EfficientNet-Lite0 features.

The paper's NetVLAD and AP-GeM were trained on real streets across seasons, times of day and
viewpoints; their weights ship in no package. This trains the same kind of layer in vlocbench's
world, on towns no experiment drives (an experiment file's towns, e.g. generated from a seed of
their own): each town's noon gallery is the map, and a query every ``query_spacing_m`` along its
route, moved sideways and turned a little at random, is rendered under one of the given setups'
conditions (the paper's illumination, weather and viewpoint levels), drawn at random. A gallery
image within ``positive_m`` of a query is a positive (the most similar one, as NetVLAD's weak
supervision takes it); those beyond ``negative_m`` in the same town are negatives, the most
similar ``negatives`` of a random thousand (similarities as of the epoch's start, NetVLAD's
cached hard negatives). The loss is NetVLAD's triplet margin loss on squared
distances. The last ``validation_towns`` towns are held out, and their recall is reported.

Everything is seeded: the same towns, setups and spec give the same weights on the same platform.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vlocbench.bench.experiment import ExperimentPlan, load_experiment
from vlocbench.bench.preparation import prepare_gallery
from vlocbench.bench.towns import route_named, town_named
from vlocbench.config import config_hash, require
from vlocbench.loc.learned import EfficientNetLite0, _inference
from vlocbench.loc.netvlad import aggregate, initial_params
from vlocbench.sim import Conditions, Simulator


@dataclass(frozen=True)
class RetrievalTraining:
    """How the training set is drawn and the head trained (the shipped weights' values)."""

    query_spacing_m: float = 2.0  # a query every this-many metres of each route (on average)
    lateral_m: float = 1.0  # queries moved up to this far sideways, uniformly
    yaw_sigma_deg: float = 3.0  # and turned by a normal angle of this deviation
    positive_m: float = 10.0
    negative_m: float = 25.0
    dim: int = 128  # D: the projected local features
    clusters: int = 32  # K: the descriptor is K * D long
    epochs: int = 8
    batch: int = 32  # queries a step
    negatives: int = 10  # hardest negatives a query
    margin: float = 0.1
    learning_rate: float = 1e-3
    validation_towns: int = 1  # the last towns of the list: held out
    width: int = 320  # the backbone's input width, pixels
    seed: int = 0

    def __post_init__(self) -> None:
        require(self.query_spacing_m > 0, "training.query_spacing_m", "must be > 0")
        require(self.lateral_m >= 0, "training.lateral_m", "must be >= 0")
        require(self.yaw_sigma_deg >= 0, "training.yaw_sigma_deg", "must be >= 0")
        require(
            0 < self.positive_m < self.negative_m,
            "training.negative_m",
            "must be greater than positive_m, which must be > 0",
        )
        for name in ("dim", "clusters", "epochs", "batch", "negatives"):
            require(getattr(self, name) >= 1, f"training.{name}", "must be >= 1")
        require(self.margin > 0, "training.margin", "must be > 0")
        require(self.learning_rate > 0, "training.learning_rate", "must be > 0")
        require(self.validation_towns >= 0, "training.validation_towns", "must be >= 0")
        require(self.width >= 32, "training.width", "must be >= 32 pixels")


def conditions_from(paths: Sequence[str | Path]) -> list[tuple[str, Conditions]]:
    """The setups of experiment files as (label, conditions), each label prefixed by its file's
    stem (``weather: weather.fog_start_m=10``), in the files' order."""
    return [
        (f"{Path(path).stem}: {s.label}", s.conditions)
        for path in paths
        for s in load_experiment(path).setups
    ]


# The spec's values that shape the rendered set (the others shape only the training).
RENDER_FIELDS = ("query_spacing_m", "lateral_m", "yaw_sigma_deg", "width", "seed")


def render_record(
    towns: ExperimentPlan, setups: Sequence[tuple[str, Conditions]], spec: RetrievalTraining
) -> dict[str, Any]:
    """What a training set is rendered from: ``spec``'s :data:`RENDER_FIELDS` and ``sources``, a
    digest of the towns' galleries (town, route, gallery drive, scene) and the setups'
    conditions."""
    record: dict[str, Any] = {f: getattr(spec, f) for f in RENDER_FIELDS}
    galleries = [towns.gallery_key(name) for name in towns.spec.towns]
    record["sources"] = config_hash((galleries, [list(s) for s in setups]), 16)
    return record


@dataclass
class TrainingSet:
    """Frozen backbone feature maps (float16) of the galleries and queries, with their places:
    ``gallery_maps`` (G, C, H, W), ``gallery_xy`` (G, 2) m, ``gallery_town`` (G,); the same for
    queries, and ``query_setup`` (Q,), an index into ``setups``. ``rendered_with``: the
    :func:`render_record` it was rendered from."""

    rendered_with: dict[str, Any]
    towns: tuple[str, ...]
    setups: tuple[str, ...]
    gallery_maps: NDArray[np.float16]
    gallery_xy: NDArray[np.float64]
    gallery_town: NDArray[np.int64]
    query_maps: NDArray[np.float16]
    query_xy: NDArray[np.float64]
    query_town: NDArray[np.int64]
    query_setup: NDArray[np.int64]

    def save(self, path: str) -> None:
        arrays = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        arrays["towns"], arrays["setups"] = np.array(self.towns), np.array(self.setups)
        arrays["rendered_with"] = np.array(json.dumps(self.rendered_with, sort_keys=True))
        with open(path, "wb") as fh:
            np.savez(fh, **arrays)

    @classmethod
    def load(cls, path: str) -> TrainingSet:
        with np.load(path, allow_pickle=False) as data:
            require(
                "rendered_with" in data.files,
                "--data",
                f"{path} does not record what it was rendered from (a set written before "
                "2026-12-07): render it again into a new file",
            )
            values = {f.name: data[f.name] for f in dataclasses.fields(cls)}
        values["rendered_with"] = json.loads(str(values["rendered_with"]))
        values["towns"] = tuple(str(t) for t in values["towns"])
        values["setups"] = tuple(str(s) for s in values["setups"])
        return cls(**values)

    def require_rendered_from(self, record: dict[str, Any], path: str) -> None:
        """Refuse a set rendered otherwise than ``record`` (a :func:`render_record`) asks, naming
        the first value that differs: trained on, it would be recorded under values it was not
        rendered with."""
        for name, wanted in record.items():
            had = self.rendered_with.get(name)
            field = "towns and --conditions" if name == "sources" else f"training.{name}"
            require(
                had == wanted,
                field,
                f"{path} was rendered with {name} = {had}, this run asks for {wanted}: pass the "
                "same values, or another --data path to render a new set",
            )


@dataclass
class TrainingReport:
    """Per epoch: the mean loss, and the held-out towns' Recall@1 and @5 within ``positive_m``
    (%); ``recall_by_setup``: the final held-out recall of each setup, label -> (R@1, R@5)."""

    loss: list[float] = field(default_factory=list)
    recall: list[tuple[float, float]] = field(default_factory=list)
    recall_by_setup: dict[str, tuple[float, float]] = field(default_factory=dict)
    seconds: float = 0.0


def render_training_set(
    towns: ExperimentPlan,
    setups: Sequence[tuple[str, Conditions]],
    spec: RetrievalTraining,
    progress: Callable[[str], None] = lambda _: None,
) -> TrainingSet:
    """The galleries of ``towns``'s towns (captured into its cache unless there) and queries
    along each route under ``setups`` ((label, conditions), one drawn per query)."""
    require(len(setups) > 0, "conditions", "needs at least one setup")
    record = render_record(towns, setups, spec)
    rng = np.random.default_rng(spec.seed)
    backbone = EfficientNetLite0(spec.width, "imagenet", "cpu")

    def described(image: NDArray[np.uint8]) -> NDArray[np.float16]:
        with _inference():
            return backbone.feature_map(image)[0].numpy().astype(np.float16)

    g: dict[str, list[Any]] = {"maps": [], "xy": [], "town": []}
    q: dict[str, list[Any]] = {"maps": [], "xy": [], "town": [], "setup": []}
    camera = dataclasses.replace(towns.spec.gallery.camera, name="query")
    names = []
    for t, name in enumerate(towns.spec.towns):
        town = town_named(name)
        names.append(town.name)
        gallery = prepare_gallery(towns, name)
        for image_name, image in zip(gallery.names, gallery.images, strict=True):
            g["maps"].append(described(gallery.load_image(image_name)))
            g["xy"].append(image.world_from_cam[:2, 3])
            g["town"].append(t)
        route = route_named(name, towns.spec.route_length_m)
        count = int(route.length_m / spec.query_spacing_m)
        s = rng.uniform(5.0, route.length_m - 5.0, count)
        lateral = rng.uniform(-spec.lateral_m, spec.lateral_m, count)
        turn = np.radians(rng.normal(0.0, spec.yaw_sigma_deg, count))
        drawn = rng.integers(0, len(setups), count)
        current = -1
        with Simulator(town) as sim:
            for j in np.argsort(drawn, kind="stable"):  # one scene change a setup
                if drawn[j] != current:
                    current = int(drawn[j])
                    sim.set_conditions(setups[current][1])
                x, y = (float(np.interp(s[j], route.s_m, route.xy[:, i])) for i in (0, 1))
                yaw = float(np.interp(s[j], route.s_m, np.unwrap(route.yaw_rad)) + turn[j])
                sim.teleport(x - lateral[j] * np.sin(yaw), y + lateral[j] * np.cos(yaw), yaw)
                [frame] = sim.render([camera])
                q["maps"].append(described(frame.image))
                q["xy"].append(frame.world_from_cam[:2, 3])
                q["town"].append(t)
                q["setup"].append(drawn[j])
        progress(f"{town.name}: {len(gallery)} gallery images, {count} queries")
    return TrainingSet(
        rendered_with=record,
        towns=tuple(names),
        setups=tuple(label for label, _ in setups),
        gallery_maps=np.stack(g["maps"]),
        gallery_xy=np.array(g["xy"]),
        gallery_town=np.array(g["town"], np.int64),
        query_maps=np.stack(q["maps"]),
        query_xy=np.array(q["xy"]),
        query_town=np.array(q["town"], np.int64),
        query_setup=np.array(q["setup"], np.int64),
    )


def train_netvlad(
    data: TrainingSet,
    spec: RetrievalTraining,
    progress: Callable[[str], None] = lambda _: None,
) -> tuple[dict[str, Any], TrainingReport]:
    """The trained head (torch tensors by name) and its report."""
    import torch

    require(
        spec.validation_towns < len(data.towns),
        "training.validation_towns",
        f"leaves no town to train on ({len(data.towns)} towns)",
    )
    t0 = time.perf_counter()
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # sums split over threads round otherwise: the same weights anywhere
    try:
        torch.manual_seed(spec.seed)
        rng = np.random.default_rng(spec.seed)
        gallery = torch.from_numpy(data.gallery_maps)
        queries = torch.from_numpy(data.query_maps)
        params = initial_params(gallery, spec.dim, spec.clusters, spec.seed)
        for p in params.values():
            p.requires_grad_(True)
        opt = torch.optim.Adam(list(params.values()), lr=spec.learning_rate)
        held_out = np.arange(len(data.towns) - spec.validation_towns, len(data.towns))
        train_q = np.flatnonzero(~np.isin(data.query_town, held_out))
        same = data.query_town[:, None] == data.gallery_town[None]
        dist = np.linalg.norm(data.query_xy[:, None] - data.gallery_xy[None], axis=2)
        positive = same & (dist <= spec.positive_m)
        negative = same & (dist > spec.negative_m)
        usable = train_q[positive[train_q].any(1) & (negative[train_q].sum(1) >= spec.negatives)]
        held_q = np.flatnonzero(np.isin(data.query_town, held_out))
        report = TrainingReport()
        # described once an epoch: the held-out recall and the next epoch's mining share them
        gallery_d, query_d = _describe(params, gallery), _describe(params, queries)
        for epoch in range(spec.epochs):
            similarity = (query_d @ gallery_d.T).numpy()
            losses = []
            order = rng.permutation(usable)
            for start in range(0, len(order), spec.batch):
                batch = order[start : start + spec.batch]
                pos, neg = [], []
                for j in batch:
                    p_idx = np.flatnonzero(positive[j])
                    pos.append(p_idx[np.argmax(similarity[j, p_idx])])
                    n_idx = np.flatnonzero(negative[j])
                    n_idx = rng.choice(n_idx, min(len(n_idx), 1000), replace=False)
                    neg.append(n_idx[np.argsort(-similarity[j, n_idx])[: spec.negatives]])
                q = aggregate(params, queries[batch])
                p = aggregate(params, gallery[np.array(pos)])
                n = aggregate(params, gallery[np.concatenate(neg)]).view(len(batch), -1, q.shape[1])
                d_pos = ((q - p) ** 2).sum(1)
                d_neg = ((q[:, None] - n) ** 2).sum(2)
                loss = torch.relu(d_pos[:, None] - d_neg + spec.margin).mean()
                opt.zero_grad()
                loss.backward()
                opt.step()
                losses.append(float(loss.detach()))
            report.loss.append(float(np.mean(losses)))
            gallery_d, query_d = _describe(params, gallery), _describe(params, queries)
            by_setup = _recall(gallery_d, query_d[held_q], held_q, data, spec.positive_m)
            report.recall.append(by_setup.pop("all", (float("nan"), float("nan"))))
            report.recall_by_setup = by_setup
            r1, r5 = report.recall[-1]
            progress(
                f"epoch {epoch + 1}/{spec.epochs}: loss {report.loss[-1]:.4f}, held-out "
                f"Recall@1 / @5 {r1:.1f} / {r5:.1f} %"
            )
        report.seconds = time.perf_counter() - t0
        return {k: v.detach() for k, v in params.items()}, report
    finally:
        torch.set_num_threads(threads)


def held_out_recall(
    params: dict[str, Any], data: TrainingSet, towns: NDArray[np.int64], radius_m: float
) -> dict[str, tuple[float, float]]:
    """Recall@1 and @5 (%) of the queries of ``towns`` against their own town's gallery, per
    setup label and over all ("all"); empty without such queries."""
    import torch

    chosen = np.flatnonzero(np.isin(data.query_town, towns))
    gallery = _describe(params, torch.from_numpy(data.gallery_maps))
    queries = _describe(params, torch.from_numpy(data.query_maps[chosen]))
    return _recall(gallery, queries, chosen, data, radius_m)


def _recall(
    gallery: Any, queries: Any, chosen: NDArray[np.int64], data: TrainingSet, radius_m: float
) -> dict[str, tuple[float, float]]:
    """:func:`held_out_recall` from descriptors: ``gallery`` of every gallery image, ``queries``
    of the queries ``chosen``, in that order."""
    if len(chosen) == 0:
        return {}
    hits = np.zeros((len(chosen), 2), bool)
    for row, j in enumerate(chosen):
        own = np.flatnonzero(data.gallery_town == data.query_town[j])
        best = own[np.argsort(-(gallery[own] @ queries[row]).numpy(), kind="stable")[:5]]
        near = np.linalg.norm(data.gallery_xy[best] - data.query_xy[j], axis=1) <= radius_m
        hits[row] = near[0], near.any()
    out = {"all": _percent(hits)}
    for s, label in enumerate(data.setups):
        mine = data.query_setup[chosen] == s
        if mine.any():
            out[label] = _percent(hits[mine])
    return out


def _percent(hits: NDArray[np.bool_]) -> tuple[float, float]:
    r1, r5 = 100.0 * hits.mean(0)
    return float(r1), float(r5)


def _describe(params: dict[str, Any], maps: Any, batch: int = 256) -> Any:
    import torch

    with torch.no_grad():
        return torch.cat(
            [aggregate(params, maps[i : i + batch]) for i in range(0, len(maps), batch)]
        )
