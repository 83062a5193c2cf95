"""Localization methods as an experiment names them: one table of localizer kinds.

A method's ``kind`` says how its localizer is built:

- ``map`` (the default): hloc-style stages (features, matcher, retrieval: a preset or registry
  names) against a map of the town's gallery; ``localizer:`` holds its settings;
- ``oracle``: the true pose with seeded noise (``args``: :class:`~vlocbench.bench.OracleConfig`),
  for how good localization must be;
- ``ros``: a localization node outside this process (``args``: :class:`RosEndpoint`);
- ``"package.module:Class"``: any class with the :class:`~vlocbench.bench.Localizer` protocol,
  built as ``Class(context, **args)`` with a :class:`MethodContext`; it brings its own map.

Each entry names the function that builds it as ``"module:function"``, imported only when a method
of its kind is built, so the optional ROS side is loaded only for ``ros`` methods. A method's kind
and arguments are part of its episodes' keys.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vlocbench.bench.localizer import Localizer, OracleConfig
from vlocbench.config import ADDED_OPTION, from_dict, require
from vlocbench.errors import ConfigError, UnknownNameError
from vlocbench.loc.localizer import LocalizerConfig
from vlocbench.loc.mapping import MappingConfig
from vlocbench.loc.registry import METHODS, MethodConf, method_conf
from vlocbench.sim import Camera


@dataclass(frozen=True)
class RosEndpoint:
    """A localization node outside this process, reached over ROS 2 (``vlocbench.ros``): each query
    image goes out on ``image_topic`` (its camera on ``camera_info_topic``), and the answer is the
    ``PoseWithCovarianceStamped`` of the base on ``pose_topic`` stamped with the image's time (a
    ``diagnostics`` status for that stamp without a pose is a failure); ``timeout_s`` (wall clock)
    without either is a failure too."""

    image_topic: str = "image"
    camera_info_topic: str = "camera_info"
    pose_topic: str = "visual_pose_estimate"
    timeout_s: float = 30.0

    def __post_init__(self) -> None:
        for name in ("image_topic", "camera_info_topic", "pose_topic"):
            require(bool(getattr(self, name)), f"ros.{name}", "must not be empty")
        require(self.timeout_s > 0, "ros.timeout_s", "must be > 0")


@dataclass(frozen=True)
class MethodContext:
    """What a localizer is built for: the method's ``name``, the rig ``cameras`` whose images each
    query carries, the ``town`` it drives, and for the ``map`` kind its map folder and the camera
    that took the map's images."""

    name: str
    cameras: tuple[Camera, ...]
    town: str = ""
    map_dir: Path | None = None
    gallery_camera: Camera | None = None


@dataclass(frozen=True)
class LocalizerKind:
    """An entry of :data:`LOCALIZER_KINDS`: ``build`` (``"module:function"``) is called as
    ``function(context, args)`` with ``args`` read into the dataclass ``args_type``."""

    build: str
    args_type: type
    needs_map: bool
    about: str


LOCALIZER_KINDS: dict[str, LocalizerKind] = {
    "map": LocalizerKind(
        "vlocbench.bench.visual:map_localizer",
        LocalizerConfig,
        True,
        "hloc-style stages against a map of the gallery (settings: localizer)",
    ),
    "oracle": LocalizerKind(
        "vlocbench.bench.localizer:oracle_localizer",
        OracleConfig,
        False,
        "the true pose with seeded noise (args: OracleConfig)",
    ),
    "ros": LocalizerKind(
        "vlocbench.ros.remote:ros_localizer",
        RosEndpoint,
        False,
        "a ROS 2 localization node outside this process (args: RosEndpoint)",
    ),
}
PLUGIN_FORM = "package.module:Class"  # any other kind: a Localizer class, built with its args
_PROTOCOL = ("localize", "reset", "close", "cameras")  # what a plugin class must define


def is_plugin(kind: str) -> bool:
    return kind not in LOCALIZER_KINDS and ":" in kind


@dataclass(frozen=True)
class MethodSpec:
    """A localization method as run by an experiment.

    ``name`` labels it in results. For the ``map`` kind it is the preset unless ``features``,
    ``matcher`` and ``retrieval`` are given (registry names or dotted paths to plugin classes);
    ``localizer`` and ``mapping`` are its map localizer's and its map's settings. Another ``kind``
    (see the module) takes its arguments in ``args``.
    """

    name: str
    features: str = ""
    matcher: str = ""
    retrieval: str = ""
    localizer: LocalizerConfig = field(default_factory=LocalizerConfig)
    mapping: MappingConfig | None = None  # this method's map settings, else the experiment's
    kind: str = field(default="map", metadata=ADDED_OPTION)
    # arguments of a kind other than map; kept out of hash(): a plugin's may be any mapping
    args: dict[str, Any] = field(default_factory=dict, hash=False, metadata=ADDED_OPTION)

    def __post_init__(self) -> None:
        require(bool(self.name), "methods.name", "must not be empty")
        where = f"methods.{self.name}"
        if self.kind not in LOCALIZER_KINDS and not is_plugin(self.kind):
            raise UnknownNameError(
                f"{where}.kind", self.kind, [*LOCALIZER_KINDS, f'"{PLUGIN_FORM}"']
            )
        require(isinstance(self.args, dict), f"{where}.args", "expected a mapping")
        parts = (self.features, self.matcher, self.retrieval)
        if self.kind != "map":
            own = self.localizer != LocalizerConfig() or self.mapping is not None or any(parts)
            require(
                not own,
                where,
                f"kind {self.kind} takes no features, matcher, retrieval, "
                "localizer or mapping settings (its own go in args)",
            )
            if self.kind in LOCALIZER_KINDS:  # a built-in kind's arguments are checked now
                from_dict(LOCALIZER_KINDS[self.kind].args_type, self.args, f"{where}.args")
            return
        require(not self.args, f"{where}.args", "the map kind's settings go under localizer")
        require(
            all(parts) or not any(parts),
            where,
            "give all of features, matcher and retrieval, or none (a preset)",
        )
        if not any(parts) and self.name not in METHODS:
            raise UnknownNameError("method", self.name, METHODS)

    @property
    def needs_map(self) -> bool:
        """Whether it localizes against a map of the gallery (the ``map`` kind)."""
        return self.kind == "map"

    @property
    def conf(self) -> MethodConf:
        if self.features:
            return MethodConf(self.features, self.matcher, self.retrieval)
        return method_conf(self.name)


def check_methods(methods: Sequence[MethodSpec]) -> None:
    """Every plugin imports, its class has the protocol's methods and takes its arguments: run
    before any work, so a typo is an error now and not in a worker hours later."""
    for m in methods:
        if is_plugin(m.kind):
            cls = _plugin_class(m)
            try:
                inspect.signature(cls).bind(MethodContext(m.name, ()), **m.args)
            except TypeError as exc:
                raise ConfigError(f"methods.{m.name}.args", f"{m.kind}: {exc}") from None


def build_localizer(method: MethodSpec, context: MethodContext) -> Localizer:
    """The localizer of ``method`` for ``context`` (in whichever process runs the episode)."""
    if is_plugin(method.kind):
        cls = _plugin_class(method)
        try:
            localizer = cls(context, **method.args)
        except TypeError as exc:  # arguments it does not take, or lacks
            raise ConfigError(f"methods.{method.name}.args", f"{method.kind}: {exc}") from None
    else:
        kind = LOCALIZER_KINDS[method.kind]
        args = method.localizer if method.kind == "map" else from_dict(kind.args_type, method.args)
        localizer = _resolve(kind.build, f"methods.{method.name}.kind")(context, args)
    missing = [a for a in ("name", "uses_ground_truth", *_PROTOCOL) if not hasattr(localizer, a)]
    if missing:
        raise ConfigError(
            f"methods.{method.name}.kind",
            f"{type(localizer).__name__} lacks {', '.join(missing)} of the "
            "Localizer protocol (vlocbench.bench.Localizer)",
        )
    return localizer


def _plugin_class(method: MethodSpec) -> type:
    where = f"methods.{method.name}.kind"
    cls = _resolve(method.kind, where)
    if not inspect.isclass(cls):
        raise ConfigError(where, f"{method.kind} is not a class")
    missing = [a for a in _PROTOCOL if not hasattr(cls, a)]
    if missing:
        raise ConfigError(
            where,
            f"{method.kind} lacks {', '.join(missing)} of the Localizer "
            "protocol (vlocbench.bench.Localizer)",
        )
    return cls


def _resolve(path: str, where: str) -> Callable[..., Any]:
    """The object ``"module:attribute"`` names; a clear error if it does not import."""
    module_name, _, attribute = path.partition(":")
    try:
        module = importlib.import_module(module_name)
    except Exception as exc:  # not found, or its own import fails: either way, named here
        raise ConfigError(where, f"cannot import {module_name} ({exc})") from None
    try:
        return getattr(module, attribute)
    except AttributeError:
        raise ConfigError(where, f"{module_name} has no {attribute}") from None
