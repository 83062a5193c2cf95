import dataclasses

from vlocbench.config import ADDED_OPTION, config_hash, default_changed


@dataclasses.dataclass(frozen=True)
class Before:
    width: int = 800


@dataclasses.dataclass(frozen=True)
class Added:
    width: int = 800
    antialias: bool = dataclasses.field(default=True, metadata=ADDED_OPTION)


@dataclasses.dataclass(frozen=True)
class Changed:
    width: int = 800
    antialias: bool = dataclasses.field(default=False, metadata=default_changed(True))


def test_an_added_option_and_a_changed_default_keep_the_stored_keys():
    stored = config_hash(Before())
    assert config_hash(Added()) == stored  # added at its default: no key changes
    assert config_hash(Added(antialias=False)) != stored
    # the default changed from True: results at the old default keep their keys, and results
    # at the new default never take them
    assert config_hash(Changed(antialias=True)) == stored
    assert config_hash(Changed()) not in (stored, config_hash(Added()))
    assert config_hash(Changed()) == config_hash(Added(antialias=False))


@dataclasses.dataclass(frozen=True)
class Rainy:
    rain: float = 0.0
    streaks: float = dataclasses.field(
        default=0.9, metadata=default_changed(0.45, only_with="rain")
    )


def test_a_field_that_needs_another_is_hashed_only_with_it():
    dry = config_hash(Rainy())
    assert config_hash(Rainy(streaks=2.0)) == dry  # no rain: its streaks change nothing
    assert config_hash(Rainy(rain=1.0, streaks=0.45)) == config_hash({"rain": 1.0})
    assert config_hash(Rainy(rain=1.0)) != config_hash(Rainy(rain=1.0, streaks=0.45))
