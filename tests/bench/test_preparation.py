"""Galleries and maps: made side by side as in turn, and one process building a folder at a time."""

from pathlib import Path

import pycolmap
import yaml

from tests.conftest import call_behind_build_lock, small_spec
from vlocbench.bench.experiment import load_experiment
from vlocbench.bench.preparation import prepare_maps
from vlocbench.config import to_dict
from vlocbench.loc.mapping import MAP_FILE


def test_galleries_and_maps_made_side_by_side_equal_those_made_in_turn(tiny, tmp_path):
    """Two towns' galleries, then maps, in two pool workers (one thread each): the tiny run's town,
    made in turn in the driver with every thread, comes out the same, image for image and point
    for point."""
    root, _ = tiny
    spec = yaml.safe_load((root / "tiny.yaml").read_text())
    other = tmp_path / "other.yaml"
    other.write_text(yaml.safe_dump(to_dict(small_spec(seed=4))))
    spec.update(towns=[spec["towns"][0], str(other)], cache=str(tmp_path / "cache"))
    maps = prepare_maps(load_experiment(spec), workers=2)
    assert len(maps) == 2 and all((Path(m) / MAP_FILE).exists() for m in maps.values())
    side_by_side = Path(maps[(spec["towns"][0], "sift")])
    in_turn = root / "cache" / side_by_side.relative_to(tmp_path / "cache")
    images = sorted((root / "cache" / "galleries").glob("*/images/*"))
    assert images
    for image in images:
        twin = tmp_path / "cache" / image.relative_to(root / "cache")
        assert image.read_bytes() == twin.read_bytes(), image.name
    points = [
        sorted(tuple(p.xyz) for p in pycolmap.Reconstruction(m / "sfm").points3D.values())
        for m in (side_by_side, in_turn)
    ]
    assert points[0] and points[0] == points[1]


def test_a_gallery_another_process_is_capturing_is_waited_for(tiny):
    """Not even a finished gallery is read while another process holds its folder."""
    from vlocbench.bench.preparation import prepare_gallery

    root, _ = tiny
    plan = load_experiment(root / "tiny.yaml")
    town = plan.spec.towns[0]
    folder = root / "cache" / "galleries" / plan.gallery_folder(town)
    gallery = call_behind_build_lock(folder, lambda: prepare_gallery(plan, town))
    assert gallery.root == folder and len(gallery) > 10
