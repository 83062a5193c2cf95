"""The project's exception hierarchy. The CLI is the only place that turns these into exit codes."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any


class VlocbenchError(Exception):
    """Base class of every error raised on purpose by vlocbench: bad input or data (exit code 1)."""

    exit_code = 1


class MachineError(VlocbenchError, RuntimeError):
    """The machine, not the input, stops it: no OpenGL, a full disk, a folder another run holds
    (exit code 3)."""

    exit_code = 3


class ConfigError(VlocbenchError, ValueError):
    """A configuration value is invalid; the message names the field and the reason."""

    def __init__(self, field: str, reason: str) -> None:
        self.field = field
        self.reason = reason
        super().__init__(f"{field}: {reason}")

    def __reduce__(self) -> tuple[type, tuple[Any, ...]]:
        # rebuilt from its fields, so that it crosses from a pool worker to the driver intact
        return type(self), (self.field, self.reason)


class UnknownNameError(ConfigError, KeyError):
    """A name (town, method, season, ...) is not one of the valid choices; the message lists them."""

    def __init__(
        self, kind: str, name: str, valid: Iterable[str], field: str | None = None
    ) -> None:
        """``field``: where the name was given (``methods[0].localizer`` for an unknown key);
        the kind of name itself when left out."""
        self.kind = kind
        self.name = name
        self.valid = sorted(valid)
        sep = "; " if any(", " in v for v in self.valid) else ", "  # names with commas: setups
        super().__init__(field or kind, f"unknown {kind} {name!r}; valid: {sep.join(self.valid)}")

    def __str__(self) -> str:  # KeyError would otherwise quote the message
        return self.args[0]

    def __reduce__(self) -> tuple[type, tuple[Any, ...]]:
        return type(self), (self.kind, self.name, self.valid, self.field)


class RenderBackendError(MachineError):
    """The headless OpenGL backend cannot start (missing libraries, bad MUJOCO_GL)."""


class PlanningError(VlocbenchError, RuntimeError):
    """No drivable route joins the requested points on the road graph."""


class LocalizationError(VlocbenchError, ValueError):
    """Bad input to the localization pipeline: an image, a gallery, a cache or a map file."""
