"""Experiment files: what to run (towns, methods, condition sweeps, repetitions) and its expansion.

An experiment YAML names towns, localization methods and a ``sweep``: a mapping from keys to
values. A key is a dotted path into :class:`~vlocbench.sim.Conditions` (``illumination.k``,
``weather.fog_visual_range_m``, ``season``, ``viewpoint``, ``traffic.cars``, ...), into the query
``camera`` (``camera.intrinsics.fov_deg``, ``camera.extrinsics.yaw_deg``) or ``cameras`` (a rig:
a list of cameras). A list of values is swept; a scalar is fixed; a list of mappings sweeps
parameters that stay together (``viewpoint: [{dz_m: 0, pitch_down_deg: 0}, {dz_m: 2, ...}]``).
Swept keys combine as a cartesian product into *setups*; each setup runs

- a recall episode per (town, method): a ground-truth drive, one repetition (it is deterministic);
- failure episodes per (town, method): navigation on the fused pose, ``repetitions`` times;
- the wheel-odometry-only baseline per town (its result depends only on traffic among the
  conditions, so setups that differ in appearance share it).

Every episode is keyed by the hash of everything that determines its result, so a rerun skips what
is done and a changed setting is a new episode, never mixed with old results.
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
import re
from collections import defaultdict
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

from vlocbench.bench.episode import EPISODE_VERSION, EpisodeConfig
from vlocbench.bench.methods import MethodSpec
from vlocbench.bench.records import EPISODE_KINDS, EpisodeKind
from vlocbench.bench.towns import route_named
from vlocbench.config import config_hash, from_dict, load_yaml, require, to_dict
from vlocbench.errors import ConfigError, UnknownNameError
from vlocbench.loc.mapping import MappingConfig, map_name
from vlocbench.sim import Camera, Conditions, gallery_camera
from vlocbench.sim.generation import is_hidden_name, town_set_names
from vlocbench.sim.scene import SCENE_VERSION
from vlocbench.sim.town import TownSpec, load_town_spec

_CONDITION_KEYS = tuple(f.name for f in dataclasses.fields(Conditions))

# The place of a retrieved image, which the place-recognition figures score. 2: where the gallery's
# car stood (through the gallery camera's mount); before, where the query camera's mount would put
# the car, metres off for a raised, tilted or turned query camera (nothing else changed: episodes
# with the gallery's mount keep their keys)
PLACE_REVISION = 2

SWEEP_ROOTS = (*_CONDITION_KEYS, "camera", "cameras", "episode", "methods")
# what of a method may be swept (methods.NAME.FIELD...): its localizer's settings and a kind's
# arguments; anything else would make another map, so it is another method
METHOD_SWEEP_FIELDS = ("localizer", "args")
# set per episode by its kind and repetition, so not sweepable
_PER_TASK_EPISODE_KEYS = ("episode.mode", "episode.seed")


@dataclass(frozen=True)
class GallerySpec:
    """The gallery drive: on the true pose at ``speed_mps``, an image every ``spacing_m`` from
    ``camera`` (the paper's: 800x600, FOV 90, facing right), which is also the default query
    camera."""

    spacing_m: float = 2.0
    speed_mps: float = 8.0
    conditions: Conditions = field(default_factory=Conditions)
    camera: Camera = field(default_factory=gallery_camera)

    def __post_init__(self) -> None:
        require(0.5 <= self.spacing_m <= 20, "gallery.spacing_m", "must be in [0.5, 20] m")
        require(0.5 <= self.speed_mps <= 20, "gallery.speed_mps", "must be in [0.5, 20] m/s")


@dataclass(frozen=True, kw_only=True)
class Setup:
    """One combination of swept values, resolved: the query conditions and cameras, and the episode
    config (the experiment's, with any ``episode.*`` sweep keys applied)."""

    label: str  # "illumination.k=3, season=winter"; "default" when nothing is swept
    levels: tuple[tuple[str, Any], ...]  # (key, value) of each swept key, in sweep order
    conditions: Conditions
    cameras: tuple[Camera, ...]
    episode: EpisodeConfig
    # the experiment's methods with this setup's ``methods.NAME.*`` values; empty: its own
    methods: tuple[MethodSpec, ...] = ()


@dataclass(frozen=True)
class ExperimentSpec:
    name: str
    towns: tuple[str, ...]
    methods: tuple[MethodSpec, ...]
    sweep: tuple[tuple[str, Any], ...] = ()  # (key, value or list of levels), as in the file
    repetitions: int = 5
    # the odometry-only line is driven max(repetitions, baseline_repetitions) times: it renders
    # nothing, so its interval can be narrow for little time
    baseline_repetitions: int = 10
    seed: int = 0
    recall: bool = True
    failure: bool = True
    baseline: bool = True
    episode: EpisodeConfig = field(default_factory=EpisodeConfig)
    mapping: MappingConfig = field(default_factory=MappingConfig)
    gallery: GallerySpec = field(default_factory=GallerySpec)
    route_length_m: float = 0.0  # > 0: drive only the first this-many metres of each town's route
    output: str = ""  # default: out/NAME
    cache: str = "out/cache"  # galleries and maps, shared between experiments

    def __post_init__(self) -> None:
        require(bool(self.name.strip()), "name", "must not be empty")
        require(len(self.towns) > 0, "towns", "needs at least one town")
        require(self.repetitions >= 1, "repetitions", "must be >= 1")
        require(self.baseline_repetitions >= 1, "baseline_repetitions", "must be >= 1")
        require(
            self.route_length_m == 0 or self.route_length_m >= 50,
            "route_length_m",
            "must be 0 (the whole route) or >= 50 m",
        )
        require(
            self.recall or self.failure or self.baseline,
            "recall/failure/baseline",
            "all false: nothing to run",
        )
        require(
            len(self.methods) > 0 or not (self.recall or self.failure),
            "methods",
            "recall and failure episodes need at least one method",
        )
        names = [m.name for m in self.methods]
        require(len(set(names)) == len(names), "methods", f"duplicate names in {names}")

    @property
    def output_dir(self) -> Path:
        return Path(self.output or f"out/{self.name}")

    @property
    def spec_hash(self) -> str:
        return config_hash(self)


@dataclass(frozen=True, kw_only=True)
class EpisodeTask:
    """One episode to run: everything a worker needs, and the key of its result."""

    kind: EpisodeKind
    town: str
    setup: Setup
    method: MethodSpec | None
    repetition: int
    episode: EpisodeConfig
    route_length_m: float = 0.0  # 0: the whole route
    key: str = ""
    map_dir: str | None = None  # the method's map folder once prepared (not part of the key)
    # the camera that took the map's images (in the key through the gallery's): where its car
    # stood is the place of a retrieved image
    gallery_camera: Camera | None = None

    @property
    def method_name(self) -> str:
        return self.method.name if self.method else "odometry"

    def on_maps(self, map_dirs: Mapping[tuple[str, str], str]) -> EpisodeTask:
        """This task with its map folder, ``map_dirs[(town, method name)]`` (as
        :func:`~vlocbench.bench.preparation.prepare_maps` returns them)."""
        if self.method is None or not self.method.needs_map:
            return self
        return dataclasses.replace(self, map_dir=map_dirs[(self.town, self.method.name)])


def _town_spec(name: str) -> TownSpec:
    return load_town_spec(name)


def _town_key(name: str) -> Any:
    """What of a town goes into its episodes' keys: its spec, or only the spec's hash for a hidden
    town (a key is stored, and a hidden town's spec must not be readable from a store)."""
    spec = _town_spec(name)
    return {"hidden": config_hash(spec, 16)} if is_hidden_name(name) else to_dict(spec)


def _towns(items: Any) -> list[str]:
    """The experiment's town names: names and spec files as given, generated sets expanded."""
    if not isinstance(items, list):
        raise ConfigError("towns", "expected a list of town names, spec files or generated sets")
    names: list[str] = []
    for k, item in enumerate(items):
        if isinstance(item, dict):
            names += town_set_names(item, f"towns[{k}]")
        elif isinstance(item, str):
            names.append(item)
        else:
            raise ConfigError(f"towns[{k}]", "expected a town name, a spec file or a mapping")
    return names


def _method(item: Any, index: int) -> MethodSpec:
    if isinstance(item, str):
        return MethodSpec(item)
    if isinstance(item, dict):
        return from_dict(MethodSpec, item, f"methods[{index}]")
    raise ConfigError(f"methods[{index}]", "expected a preset name or a mapping")


def load_experiment(source: str | Path | Mapping[str, Any]) -> ExperimentPlan:
    """An experiment from a YAML file (or its parsed mapping), validated and resolved into its plan."""
    data = load_yaml(source) if isinstance(source, str | Path) else dict(source)
    if not isinstance(data, dict):
        raise ConfigError(str(source), "an experiment file must be a mapping")
    data = dict(data)
    methods = data.pop("methods", [])
    sweep = data.pop("sweep", {}) or {}
    if not isinstance(methods, list):
        raise ConfigError("methods", "expected a list of preset names or mappings")
    if not isinstance(sweep, dict):
        raise ConfigError("sweep", "expected a mapping of keys to values or lists of values")
    towns = data.get("towns")
    if towns is not None:
        data["towns"] = _towns([towns] if isinstance(towns, str) else towns)
    if "name" not in data and isinstance(source, str | Path):
        data["name"] = Path(source).stem
    data["methods"] = [_method(m, i) for i, m in enumerate(methods)]
    data["sweep"] = [(str(k), v) for k, v in sweep.items()]
    return resolve(from_dict(ExperimentSpec, data))


def resolve(spec: ExperimentSpec) -> ExperimentPlan:
    """The plan of a validated spec: every town checked, every sweep point resolved."""
    for town in spec.towns:
        _town_spec(town)
        if spec.route_length_m > 0:  # a cut longer than the route would silently drive it whole
            route_m = route_named(town).length_m
            require(
                spec.route_length_m <= route_m,
                "route_length_m",
                f"{spec.route_length_m:g} m is longer than {town}'s route ({route_m:.0f} m)",
            )
    sweep = _sweep_levels(spec)
    return ExperimentPlan(
        spec=spec,
        setups=_resolve_setups(spec, sweep),
        axis=tuple(k for k, levels in sweep if len(levels) > 1),
    )


@dataclass(frozen=True, kw_only=True)
class ExperimentPlan:
    """An experiment resolved once: its spec (as validated, for its hash and the store), its setups
    and the swept keys. The runner, the summary and the report read only this; the store keeps it,
    so a report needs nothing else (and shows what was run even after the defaults change)."""

    spec: ExperimentSpec
    setups: tuple[Setup, ...]
    axis: tuple[str, ...]  # the keys that take more than one level: the result tables' axes

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def output_dir(self) -> Path:
        return self.spec.output_dir

    def camera_mismatches(self) -> list[str]:
        """The setups whose queries the camera records through another tone curve than the
        gallery's (the map and the queries from different cameras: rarely meant), each said."""
        gallery = self.spec.gallery.conditions.exposure.tone_curve
        return [
            f"setup {s.label}: its queries go through the {s.conditions.exposure.tone_curve} "
            f"tone curve, the gallery through {gallery} (for one camera set gallery: "
            f"{{conditions: {{exposure: {{tone_curve: {s.conditions.exposure.tone_curve}}}}}}})"
            for s in self.setups
            if s.conditions.exposure.tone_curve != gallery
        ]

    def with_output(self, output: str | Path) -> ExperimentPlan:
        """The same plan writing its results to ``output``."""
        return dataclasses.replace(self, spec=dataclasses.replace(self.spec, output=str(output)))

    def only(
        self,
        towns: Sequence[str] = (),
        methods: Sequence[str] = (),
        kinds: Sequence[str] = (),
        setups: Sequence[str] = (),
        repetitions: int | None = None,
    ) -> ExperimentPlan:
        """The part of the plan in ``towns``, with ``methods``, of the episode ``kinds`` (recall,
        failure, baseline) and in the ``setups`` of its sweep (by label, ``illumination.k=0``, or
        without the key's first part, ``k=0``; where several keys are swept, one key's level
        names every setup at that level: ``k=8`` both of ``k=8, episode.ekf.late_measurements=
        current`` and ``...=replay``); empty: all of them. ``repetitions``: only the
        first so many failure and odometry-only drives of each setup (the whole shape of a long
        sweep before its spread); None: all. Its episodes keep their keys, so a later run of the
        whole plan reuses them."""
        s = self.spec
        if repetitions is not None:
            require(
                1 <= repetitions <= s.repetitions,
                "repetitions",
                f"must be from 1 to the experiment's {s.repetitions}, got {repetitions}",
            )
        planned = [k for k in EPISODE_KINDS if getattr(s, k)]
        named = {x.label: setup_names(x) for x in self.setups}
        choices = {
            "town": (towns, s.towns),
            "method": (methods, [m.name for m in s.methods]),
            "episode kind": (kinds, planned),
            "setup": (setups, list(dict.fromkeys(n for ns in named.values() for n in ns))),
        }
        for kind, (names, valid) in choices.items():
            for name in names:
                if name not in valid:
                    raise UnknownNameError(kind, name, valid)  # valid: the experiment's own
        part = dataclasses.replace(
            s,
            towns=tuple(t for t in s.towns if not towns or t in towns),
            methods=tuple(m for m in s.methods if not methods or m.name in methods),
            recall=s.recall and (not kinds or "recall" in kinds),
            failure=s.failure and (not kinds or "failure" in kinds),
            baseline=s.baseline and (not kinds or "baseline" in kinds),
            repetitions=repetitions or s.repetitions,
            # the first drives of the odometry line: as many as of each method
            baseline_repetitions=repetitions or s.baseline_repetitions,
        )
        chosen = tuple(x for x in self.setups if not setups or set(setups) & set(named[x.label]))
        return dataclasses.replace(self, spec=part, setups=chosen)

    def methods_of(self, setup: Setup) -> tuple[MethodSpec, ...]:
        """The plan's methods as ``setup`` runs them, its swept ``methods.NAME.*`` values set (a
        part of the plan, :meth:`only`, keeps its own methods)."""
        names = {m.name for m in self.spec.methods}
        return tuple(m for m in setup.methods or self.spec.methods if m.name in names)

    def gallery_key(self, town: str) -> str:
        """What determines a town's gallery: the town, the route, the drive and the scene
        version."""
        s = self.spec
        return config_hash((_town_key(town), s.route_length_m, s.gallery, SCENE_VERSION), 10)

    def gallery_folder(self, town: str) -> str:
        """The folder of a town's gallery in the cache: ``TOWN-GALLERYKEY``. Its maps lie under
        this name and the gallery's content hash (:attr:`~vlocbench.loc.Gallery.identity`)."""
        return f"{_town_spec(town).name}-{self.gallery_key(town)}"

    def map_name(self, method: MethodSpec) -> str:
        """The folder of a method's map, under its gallery's."""
        return map_name(method.conf, method.mapping or self.spec.mapping)

    def tasks(self) -> list[EpisodeTask]:
        """Every episode of the plan, once per key: setups that differ only in appearance share
        their baseline episodes. A task's map folder is bound later (:meth:`EpisodeTask.on_maps`):
        keys depend on what determines the maps, not on where they lie."""
        tasks: dict[str, EpisodeTask] = {}
        for task in self.episodes():
            tasks.setdefault(task.key, task)
        return list(tasks.values())

    def episodes(self) -> Iterator[EpisodeTask]:
        """Every (town, setup, job) of the plan, so that a baseline episode comes once for each
        setup it serves: how the summary finds each setup's episodes in a store."""
        for town in self.spec.towns:
            town_dict = _town_key(town)
            for setup in self.setups:
                for kind, method, rep in self._jobs(setup):
                    yield self._task(town, town_dict, setup, kind, method, rep)

    @cached_property
    def cells_by_key(self) -> Mapping[str, tuple[tuple[str, str, str], ...]]:
        """Each episode key's (town, method, setup label) cells: its setup's, or every setup an
        odometry-only drive serves. Computed once a plan: its keys hash every episode's
        configuration."""
        out: dict[str, list[tuple[str, str, str]]] = defaultdict(list)
        for task in self.episodes():
            cell = (task.town, task.method_name, task.setup.label)
            if cell not in out[task.key]:
                out[task.key].append(cell)
        return {k: tuple(v) for k, v in out.items()}

    @cached_property
    def setups_by_key(self) -> Mapping[str, tuple[str, ...]]:
        """Each episode key's setup labels (of :attr:`cells_by_key`). A stored episode's own
        label is the plan's it was run under, which another plan of the same episode (a sweep
        grown by a key) names otherwise."""
        return {
            key: tuple(label for _, _, label in cells) for key, cells in self.cells_by_key.items()
        }

    def _jobs(self, setup: Setup) -> list[tuple[EpisodeKind, MethodSpec | None, int]]:
        s = self.spec
        jobs: list[tuple[EpisodeKind, MethodSpec | None, int]] = []
        for method in self.methods_of(setup):
            if s.recall:
                jobs.append(("recall", method, 0))
            if s.failure:
                jobs += [("failure", method, r) for r in range(s.repetitions)]
        if s.baseline:
            runs = max(s.repetitions, s.baseline_repetitions)
            jobs += [("baseline", None, r) for r in range(runs)]
        return jobs

    def _task(
        self,
        town: str,
        town_dict: Any,
        setup: Setup,
        kind: EpisodeKind,
        method: MethodSpec | None,
        rep: int,
    ) -> EpisodeTask:
        config = dataclasses.replace(
            setup.episode,
            mode="ground_truth" if kind == "recall" else "navigate",
            seed=self.spec.seed + rep,
        )
        with_map = method is not None and method.needs_map
        world = (
            baseline_drive(setup.conditions)
            if method is None  # the baseline renders nothing
            else {"conditions": setup.conditions, "cameras": setup.cameras}
        )
        # what determines the result, nothing of where it lies: the gallery by its key (the
        # town, the route, the drive, the scene version), the map by its name (the method's
        # configuration and the mapping settings)
        identity: dict[str, Any] = {
            "kind": kind,
            "town": town_dict,
            "scene": SCENE_VERSION,
            "episode_version": EPISODE_VERSION,
            "route_length_m": self.spec.route_length_m,
            "world": world,
            "method": method,
            "map": self.map_name(method) if with_map and method else None,
            "gallery": self.gallery_key(town) if with_map else None,
            "episode": config,
        }
        gallery_camera = self.spec.gallery.camera
        if with_map and _mounted_otherwise(setup, gallery_camera):
            identity["place"] = PLACE_REVISION  # only where the stored figures changed with it
        return EpisodeTask(
            kind=kind,
            town=town,
            setup=setup,
            method=method,
            repetition=rep,
            episode=config,
            route_length_m=self.spec.route_length_m,
            key=config_hash(identity, 16),
            gallery_camera=gallery_camera if with_map else None,
        )


def _mounted_otherwise(setup: Setup, gallery_camera: Camera) -> bool:
    """Whether the setup's first query camera, as rendered (the viewpoint's change applied), is
    mounted other than the gallery camera."""
    vp = setup.conditions.viewpoint
    first = setup.cameras[0].offset(vp.dz_m, vp.pitch_down_deg)
    return first.extrinsics != gallery_camera.extrinsics


# what an odometry-only drive depends on among a setup's conditions: the traffic alone (it renders
# nothing), so setups that differ in appearance share its episodes (and its key)
BASELINE_CONDITIONS = ("traffic",)


def baseline_drive(conditions: Conditions) -> dict[str, Any]:
    """The part of ``conditions`` an odometry-only drive depends on (:data:`BASELINE_CONDITIONS`)."""
    return {name: getattr(conditions, name) for name in BASELINE_CONDITIONS}


def plan_from_stored(data: dict[str, Any]) -> ExperimentPlan:
    """The plan a run stored (``to_dict`` of it); a run stored before plans were kept holds the
    spec alone, which is resolved again."""
    if "setups" in data:
        return from_dict(ExperimentPlan, data)
    return load_experiment({**data, "sweep": {k: v for k, v in data.get("sweep", [])}})


def set_dotted(tree: dict[str, Any], dotted: str, value: Any, name: str) -> None:
    """Set ``tree``'s field at the dotted path ``dotted`` (groups made as needed; a dict value
    updates a dict there); ``name`` is what an error calls it."""
    *parents, leaf = dotted.split(".")
    for p in parents:
        node = tree.setdefault(p, {})
        if not isinstance(node, dict):
            raise ConfigError(name, f"{p} is set to a value and also has sub-keys")
        tree = node
    if isinstance(value, dict) and isinstance(tree.get(leaf), dict):
        tree[leaf].update(value)
    else:
        tree[leaf] = value


def _levels(key: str, value: Any) -> list[Any]:
    """The levels a sweep key takes: a list sweeps, anything else is one fixed level."""
    if key == "cameras":  # a rig is itself a list: a list of rigs sweeps, one rig is fixed
        swept = isinstance(value, list) and bool(value) and all(isinstance(v, list) for v in value)
        levels = value if swept else [value]
    else:
        levels = value if isinstance(value, list) else [value]
    if not levels or levels == [[]]:
        raise ConfigError(f"sweep.{key}", "an empty list expands to zero runs")
    return levels


def setup_label_of(labels: Mapping[str, tuple[str, ...]], key: str, stored: str) -> str:
    """The setup a plan names a stored episode by (``labels``: its
    :attr:`~ExperimentPlan.setups_by_key`): the label it was ``stored`` under where that is one
    of the key's (an odometry-only drive serves several), else the key's first; the stored one
    for a key the plan has not."""
    here = labels.get(key, ())
    return stored if stored in here or not here else here[0]


def setup_names(setup: Setup) -> tuple[str, ...]:
    """What names ``setup`` on the command line: its label and its short label
    (:func:`short_label`), and where several keys are swept, each key's level alone, long and
    short (``illumination.k=8``, ``k=8``)."""
    labels = [setup.label] + [_label(k, v) for k, v in setup.levels]
    return tuple(dict.fromkeys(n for x in labels for n in (x, short_label(x))))


def short_label(label: str) -> str:
    """A setup's label without its first key's first part: ``k=0`` for ``illumination.k=0``, and a
    grouped level's fields alone, ``dz_m=4, pitch_down_deg=22.5`` for ``viewpoint(dz_m=4,
    pitch_down_deg=22.5)``. Values are not keys: a dot or a bracket inside them is kept."""
    key = re.match(r"[A-Za-z_]\w*([.(])", label)
    if key is None:
        return label
    if key.group(1) == ".":
        return label[key.end() :]
    close = label.index(")", key.end())
    return label[key.end() : close] + label[close + 1 :]


def _label(key: str, value: Any) -> str:
    """A level's part of a setup's identity: canonical (a grouped level's keys sorted), so the file,
    the store (which keeps JSON with sorted keys) and the report all name a setup alike."""
    if isinstance(value, dict):
        return f"{key}(" + ", ".join(f"{k}={value[k]}" for k in sorted(value)) + ")"
    if key == "cameras":
        return f"cameras={len(value)}"
    return f"{key}={value}"


def _camera(base: Camera, overrides: Any, name: str, field: str) -> Camera:
    """``base`` with the keys of ``overrides`` (a Camera mapping, nested keys merged) changed."""
    if not isinstance(overrides, dict):
        raise ConfigError(field, "expected a mapping of camera settings")
    merged = {**to_dict(base), "name": name}
    _merge(merged, overrides)
    return from_dict(Camera, merged, field)


def _sweep_levels(spec: ExperimentSpec) -> list[tuple[str, list[Any]]]:
    """Each sweep key with its levels, in the file's order (validated keys)."""
    keys = []
    for key, value in spec.sweep:
        root = key.split(".")[0]
        if root not in SWEEP_ROOTS:
            raise UnknownNameError("sweep key", key, SWEEP_ROOTS)
        if key in _PER_TASK_EPISODE_KEYS or key == "episode":
            raise ConfigError(f"sweep.{key}", "is set per episode by its kind and repetition")
        if root == "methods":
            _check_method_key(spec, key)
        keys.append((key, _levels(key, value)))
    return keys


def _check_method_key(spec: ExperimentSpec, key: str) -> None:
    """``methods.NAME.FIELD...``: NAME one of the experiment's methods, FIELD one it may sweep."""
    parts = key.split(".")
    names = [m.name for m in spec.methods]
    if len(parts) < 3:
        raise ConfigError(
            f"sweep.{key}", "expected methods.NAME.localizer... or methods.NAME.args..."
        )
    if parts[1] not in names:
        raise UnknownNameError(f"sweep.{key}: method", parts[1], names)
    require(
        parts[2] in METHOD_SWEEP_FIELDS,
        f"sweep.{key}",
        f"a method's {parts[2]} cannot be swept (only {', '.join(METHOD_SWEEP_FIELDS)}: other "
        "settings make another map; list it as another method)",
    )


def _methods(spec: ExperimentSpec, overrides: dict[str, Any] | None) -> tuple[MethodSpec, ...]:
    """The experiment's methods with a setup's swept ``methods.NAME.*`` values (checked as the
    method's own fields are); empty when none is swept."""
    if not overrides:
        return ()
    out = []
    for method in spec.methods:
        if method.name not in overrides:
            out.append(method)
            continue
        merged = to_dict(method)
        _merge(merged, overrides[method.name])
        try:
            out.append(from_dict(MethodSpec, merged))
        except ConfigError as exc:  # it names the method's own field: say that a sweep set it
            raise ConfigError(f"sweep.methods.{method.name}", str(exc)) from None
    return tuple(out)


def _resolve_setups(spec: ExperimentSpec, sweep: list[tuple[str, list[Any]]]) -> tuple[Setup, ...]:
    """The cartesian product of the swept keys, as resolved setups (validated)."""
    swept = [k for k, levels in sweep if len(levels) > 1]
    out = []
    for combo in itertools.product(*(levels for _, levels in sweep)):
        tree: dict[str, Any] = {}
        for (key, _), value in zip(sweep, combo):
            set_dotted(tree, key, copy.deepcopy(value), f"sweep.{key}")
        episode = _episode(spec.episode, tree.pop("episode", None))
        methods = _methods(spec, tree.pop("methods", None))
        cameras = _cameras(spec.gallery.camera, tree.pop("cameras", None), tree.pop("camera", None))
        conditions = from_dict(Conditions, tree, "sweep")
        levels = tuple((k, v) for (k, _), v in zip(sweep, combo) if k in swept)
        label = ", ".join(_label(k, v) for k, v in levels) or "default"
        out.append(
            Setup(
                label=label,
                levels=levels,
                conditions=conditions,
                cameras=cameras,
                episode=episode,
                methods=methods,
            )
        )
    labels = [s.label for s in out]
    require(len(set(labels)) == len(labels), "sweep", "two setups have the same levels")
    return tuple(out)


def _episode(base: EpisodeConfig, overrides: dict[str, Any] | None) -> EpisodeConfig:
    """``base`` with the swept ``episode.*`` values set (nested configs merged)."""
    if not overrides:
        return base
    merged = to_dict(base)
    _merge(merged, overrides)
    return from_dict(EpisodeConfig, merged, "sweep.episode")


def _merge(tree: dict[str, Any], overrides: dict[str, Any]) -> None:
    for k, v in overrides.items():
        if isinstance(v, dict) and isinstance(tree.get(k), dict):
            _merge(tree[k], v)
        else:
            tree[k] = v


def _cameras(gallery: Camera, cams: Any, cam: Any) -> tuple[Camera, ...]:
    """The query rig: ``cameras`` (a list), or the gallery camera with ``camera``'s changes."""
    require(cams is None or cam is None, "sweep", "set either camera or cameras, not both")
    if cams is None:
        return (_camera(gallery, {"name": "query", **(cam or {})}, "query", "sweep.camera"),)
    if not isinstance(cams, list) or not cams:
        raise ConfigError("sweep.cameras", "expected a list of cameras (a rig)")
    cameras = tuple(
        _camera(gallery, c, f"cam{i}", f"sweep.cameras[{i}]") for i, c in enumerate(cams)
    )
    names = [c.name for c in cameras]
    require(len(set(names)) == len(names), "sweep.cameras", f"duplicate names {names}")
    return cameras
