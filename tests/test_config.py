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
