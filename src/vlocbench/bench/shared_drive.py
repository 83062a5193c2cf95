"""Recall drives of several methods on one simulated drive.

A ``ground_truth`` drive steers on the true pose, so the car's path, its failures and the images its
cameras take at each localization tick do not depend on the localizer, as long as the ticks do not
(a ``fixed`` or no latency; a ``measured`` one moves them). The recall episodes of several methods in
one setup therefore share a drive: the first (the lead) steps the real simulator and renders; the
others follow in turns, step by step, on a log of what the simulator answered the lead. Each image is
rendered once, and the log holds one step at a time. Each episode gets its own copy of every image,
so a localizer that writes into its input changes no other's. Localizers with the same feature
extractor extract each image once (:func:`vlocbench.loc.features.shared_extraction`); each still
counts the extraction in its compute time.

Every result is the one the episode gives on its own, except for wall times (the lead's include the
simulator and the renders). A follower that asks the simulator anything the lead did not ask at the
same point has diverged: that is a bug, and raises :class:`SharedDriveError`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from vlocbench.bench.episode import Episode, EpisodeConfig
from vlocbench.bench.localizer import Localizer
from vlocbench.bench.records import EpisodeResult
from vlocbench.interfaces import Control
from vlocbench.loc.features import shared_extraction
from vlocbench.nav import WaypointPath
from vlocbench.sim import Camera, Frame, Simulator, StepResult, VehicleParams, VehicleState

_T = TypeVar("_T")


class SharedDriveError(RuntimeError):
    """A follower's drive left the lead's: the drive was not independent of the localizer."""


def can_share(config: EpisodeConfig) -> bool:
    """Whether episodes of ``config`` drive alike for every localizer."""
    return config.mode == "ground_truth" and config.latency.mode != "measured"


class _SimLog:
    """The lead's calls to the simulator, ``(call, arguments, answer)``, kept until every
    follower has read them."""

    def __init__(self, followers: int) -> None:
        self.events: list[tuple[str, Any, Any]] = []
        self.first = 0  # the index of events[0] in the whole drive
        self.cursors = dict.fromkeys(range(followers), 0)

    def add(self, call: str, args: tuple[Any, ...], answer: _T) -> _T:
        if self.cursors:
            self.events.append((call, args, answer))
        return answer

    def read(self, follower: int, call: str, args: tuple[Any, ...]) -> Any:
        at = self.cursors[follower]
        if at - self.first >= len(self.events):
            raise SharedDriveError(
                f"follower {follower} called {call}{args} beyond the lead's calls"
            )
        lead_call, lead_args, answer = self.events[at - self.first]
        if (call, args) != (lead_call, lead_args):
            raise SharedDriveError(
                f"follower {follower} called {call}{args} where the lead called "
                f"{lead_call}{lead_args} (call {at} of the drive)"
            )
        self.cursors[follower] = at + 1
        return answer

    def leave(self, follower: int) -> None:
        self.cursors.pop(follower, None)

    def trim(self) -> None:
        """Drop what every follower has read."""
        done = min(self.cursors.values(), default=self.first + len(self.events))
        del self.events[: done - self.first]
        self.first = done


class _SharedSim:
    """An episode's view of the shared simulator: its step and vehicle are the real one's."""

    def __init__(self, sim: Simulator, log: _SimLog) -> None:
        self.sim, self.log = sim, log

    @property
    def dt_s(self) -> float:
        return self.sim.dt_s

    @property
    def params(self) -> VehicleParams:
        return self.sim.params


class _LeadSim(_SharedSim):
    """The real simulator, each answer logged for the followers."""

    @property
    def state(self) -> VehicleState:
        return self.log.add("state", (), self.sim.state)

    def set_vehicle(self, vehicle: VehicleParams) -> None:
        self.sim.set_vehicle(vehicle)
        self.log.add("set_vehicle", (vehicle,), None)

    def reset(self, x_m: float, y_m: float, yaw_rad: float) -> VehicleState:
        return self.log.add("reset", (x_m, y_m, yaw_rad), self.sim.reset(x_m, y_m, yaw_rad))

    def teleport(self, x_m: float, y_m: float, yaw_rad: float) -> VehicleState:
        answer = self.sim.teleport(x_m, y_m, yaw_rad)
        return self.log.add("teleport", (x_m, y_m, yaw_rad), answer)

    def step(self, control: Control) -> StepResult:
        return self.log.add("step", (control,), self.sim.step(control))

    def render(self, cameras: Sequence[Camera]) -> list[Frame]:
        frames = self.log.add("render", (tuple(cameras),), self.sim.render(cameras))
        return _copies(frames) if self.log.cursors else frames


class _FollowSim(_SharedSim):
    """A follower's simulator: the lead's answers, read from the log in the lead's order."""

    def __init__(self, sim: Simulator, log: _SimLog, follower: int) -> None:
        super().__init__(sim, log)
        self.follower = follower

    def _read(self, call: str, *args: Any) -> Any:
        return self.log.read(self.follower, call, args)

    @property
    def state(self) -> VehicleState:
        return self._read("state")

    def set_vehicle(self, vehicle: VehicleParams) -> None:
        self._read("set_vehicle", vehicle)

    def reset(self, x_m: float, y_m: float, yaw_rad: float) -> VehicleState:
        return self._read("reset", x_m, y_m, yaw_rad)

    def teleport(self, x_m: float, y_m: float, yaw_rad: float) -> VehicleState:
        return self._read("teleport", x_m, y_m, yaw_rad)

    def step(self, control: Control) -> StepResult:
        return self._read("step", control)

    def render(self, cameras: Sequence[Camera]) -> list[Frame]:
        return _copies(self._read("render", tuple(cameras)))


def _copies(frames: list[Frame]) -> list[Frame]:
    """Frames with images of their own: what one episode's localizer does to them stays there."""
    return [dataclasses.replace(f, image=f.image.copy()) for f in frames]


def run_shared_drive(
    sim: Simulator,
    path: WaypointPath,
    localizers: Sequence[Localizer],
    config: EpisodeConfig,
) -> list[EpisodeResult | Exception]:
    """Drive ``path`` once on the true pose for every localizer of ``localizers`` (which must ask
    for the same cameras); returns each one's result, in order, or the exception its episode raised.
    A lead that raises hands the drive to the next localizer, which drives it again."""
    if not can_share(config):
        raise ValueError("only ground_truth episodes without a measured latency share a drive")
    if not localizers:
        return []
    cameras = {tuple(loc.cameras) for loc in localizers}
    if len(cameras) > 1:
        raise ValueError("localizers that share a drive must ask for the same cameras")
    log = _SimLog(len(localizers) - 1)
    outcomes: list[EpisodeResult | Exception | None] = [None] * len(localizers)
    try:
        with shared_extraction():
            _drive(sim, path, localizers, config, log, outcomes)
    except Exception as exc:  # the lead's: the others drive again without it
        outcomes[0] = exc
        rest = [k for k in range(1, len(localizers)) if outcomes[k] is None]
        again = run_shared_drive(sim, path, [localizers[k] for k in rest], config)
        for k, outcome in zip(rest, again):
            outcomes[k] = outcome
    return [o for o in outcomes if o is not None]


def _drive(
    sim: Simulator,
    path: WaypointPath,
    localizers: Sequence[Localizer],
    config: EpisodeConfig,
    log: _SimLog,
    outcomes: list[EpisodeResult | Exception | None],
) -> None:
    """The drive of :func:`run_shared_drive`, each outcome set in ``outcomes`` as its episode
    ends (a follower that raises leaves the drive); what the lead raises propagates."""
    lead = Episode(_LeadSim(sim, log), path, localizers[0], config)
    followers: dict[int, Episode] = {}
    for k, loc in enumerate(localizers[1:]):
        try:
            followers[k] = Episode(_FollowSim(sim, log, k), path, loc, config)
        except Exception as exc:
            outcomes[k + 1] = exc
            log.leave(k)
    lead.start()
    _each(followers, log, outcomes, Episode.start)
    while lead.running:
        lead.advance()
        _each(followers, log, outcomes, Episode.advance)
        log.trim()
    outcomes[0] = lead.finish()  # the end's calls to the simulator, then the followers'
    _each(followers, log, outcomes, _finish)


def _finish(episode: Episode) -> EpisodeResult:
    if episode.running:  # its progress has left the lead's
        raise SharedDriveError("a follower still drives after the lead's drive ended")
    return episode.finish()


def _each(
    followers: dict[int, Episode],
    log: _SimLog,
    outcomes: list[EpisodeResult | Exception | None],
    action: Callable[[Episode], EpisodeResult | None],
) -> None:
    """``action`` on every follower still in the drive (a result it returns is the follower's
    outcome); one that raises leaves the drive with that as its outcome."""
    for k, episode in list(followers.items()):
        result: EpisodeResult | Exception | None
        try:
            result = action(episode)
        except Exception as exc:
            result = exc
        if result is not None:
            outcomes[k + 1] = result
        if isinstance(result, Exception):
            followers.pop(k)
            log.leave(k)
