"""Frozen-dataclass configs: strict loading from plain dicts / YAML, and stable hashes.

Every config in vlocbench is a frozen dataclass. ``from_dict`` builds one from YAML data, rejecting
unknown keys (listing the valid ones) and converting lists to tuples; each dataclass validates its
own values in ``__post_init__`` and raises ``ConfigError`` naming the field.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml

from vlocbench.errors import ConfigError, UnknownNameError

# set (to anything but "" or "0") to let native libraries log everything (``vlocbench -v`` sets it;
# worker processes inherit it): see vlocbench.loc.native
NATIVE_LOG_ENV = "VLOCBENCH_NATIVE_LOG"

T = TypeVar("T")


def load_yaml(path: str | Path) -> Any:
    """Read a YAML file; a syntax error becomes a ConfigError naming the file."""
    path = Path(path)
    try:
        return yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise ConfigError(str(path), "file not found") from None
    except yaml.YAMLError as exc:
        raise ConfigError(str(path), f"invalid YAML: {exc}") from None


def _convert(value: Any, annotation: Any, field: str) -> Any:
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if annotation is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        options = [a for a in args if a is not type(None)]
        if len(options) == 1:  # an optional value: its own error names its own field
            return _convert(value, options[0], field)
        errors = []
        for arg in (a for a in args if a is not type(None)):
            try:
                return _convert(value, arg, field)
            except ConfigError as exc:
                errors.append(exc.reason)
        raise ConfigError(field, "; ".join(errors))
    if origin is typing.Literal:
        if value not in args:
            raise UnknownNameError(field, str(value), [str(a) for a in args])
        return value
    if dataclasses.is_dataclass(annotation):
        if isinstance(annotation, type) and isinstance(value, annotation):
            return value
        return from_dict(annotation, value, field)  # type: ignore[arg-type]
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(field, f"expected a list, got {type(value).__name__}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(v, args[0], f"{field}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(field, f"expected {len(args)} values, got {len(value)}")
        return tuple(_convert(v, a, f"{field}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
    if annotation is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(field, f"expected a number, got {value!r}")
        return float(value)
    if annotation is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(field, f"expected an integer, got {value!r}")
        return value
    if annotation is bool:
        if not isinstance(value, bool):
            raise ConfigError(field, f"expected true or false, got {value!r}")
        return value
    if annotation is str:
        if not isinstance(value, str):
            raise ConfigError(field, f"expected a string, got {value!r}")
        return value
    return value


def from_dict(cls: type[T], data: Any, field: str = "") -> T:
    """Build the frozen dataclass ``cls`` from ``data`` (a mapping), strictly.

    Unknown keys raise ``UnknownNameError`` listing the valid keys; values are converted to the
    annotated types (lists to tuples, nested dataclasses recursively).
    """
    name = field or cls.__name__
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(name, f"expected a mapping, got {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}  # type: ignore[arg-type]
    kwargs = {}
    for key, value in data.items():
        if key not in fields:
            raise UnknownNameError("key", str(key), fields, field=name)
        kwargs[key] = _convert(value, hints[key], f"{name}.{key}" if field else key)
    try:
        return cls(**kwargs)
    except ConfigError as exc:
        if field and not exc.field.startswith(field):
            # a dataclass names its fields from its own root ("illumination.k"): don't repeat it
            last = field.rsplit(".", 1)[-1]
            tail = exc.field.removeprefix(f"{last}.")
            raise ConfigError(f"{field}.{tail}", exc.reason) from None
        raise


def to_dict(config: Any) -> Any:
    """Plain (JSON/YAML-ready) form of a dataclass config: tuples become lists."""
    if dataclasses.is_dataclass(config) and not isinstance(config, type):
        return {f.name: to_dict(getattr(config, f.name)) for f in dataclasses.fields(config)}
    if isinstance(config, list | tuple):
        return [to_dict(v) for v in config]
    if isinstance(config, dict):
        return {str(k): to_dict(v) for k, v in config.items()}
    return config


# field metadata of an option added after results were stored: at its default it is left out of
# config_hash, so that adding it changes no existing key
ADDED_OPTION = {"hash": "omit_default"}


def default_changed(was: Any, *, only_with: str | None = None) -> dict[str, Any]:
    """Field metadata of an ADDED_OPTION whose default later changed from ``was``: at ``was`` it
    is still left out of config_hash (stored keys still match), at the new default it is not (so
    results at the new default never take the old ones' keys). ``only_with``: a field of the same
    config without which this one does nothing (the rain's streaks without rain); where that one
    is falsy, this one is left out of the hash whatever its value."""
    return {"hash": "omit_value", "omit": was, "only_with": only_with}


def hashed_values(config: Any) -> Any:
    """``to_dict`` for hashing: ADDED_OPTION fields at their default are left out, and fields
    whose ``only_with`` field is falsy."""
    if dataclasses.is_dataclass(config) and not isinstance(config, type):
        out = {}
        for f in dataclasses.fields(config):
            value = getattr(config, f.name)
            rule = f.metadata.get("hash")
            if f.metadata.get("only_with") and not getattr(config, f.metadata["only_with"]):
                continue
            if rule == "omit_default" and value == _default(f):
                continue
            if rule == "omit_value" and value == f.metadata["omit"]:
                continue
            out[f.name] = hashed_values(value)
        return out
    if isinstance(config, list | tuple):
        return [hashed_values(v) for v in config]
    if isinstance(config, dict):
        return {str(k): hashed_values(v) for k, v in config.items()}
    return config


def _default(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return dataclasses.MISSING


def config_hash(config: Any, length: int = 12) -> str:
    """A stable short hash of a config's resolved values (canonical JSON, SHA-256)."""
    text = json.dumps(hashed_values(config), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:length]


def require(condition: bool, field: str, reason: str) -> None:
    """Raise ``ConfigError(field, reason)`` unless ``condition`` holds."""
    if not condition:
        raise ConfigError(field, reason)


def require_one_of(value: Any, valid: typing.Iterable[Any], field: str) -> None:
    """Raise ``UnknownNameError`` (listing the valid ones) unless ``value`` is one of ``valid``:
    named options built directly, not through ``from_dict``, are checked as strictly."""
    valid = tuple(valid)
    if value not in valid:
        raise UnknownNameError(field, str(value), [str(v) for v in valid])
