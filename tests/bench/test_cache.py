"""The shared cache: what it holds, what experiments still use, and freeing the rest."""

import fcntl
import json

import numpy as np
import pytest

from vlocbench.bench import cache
from vlocbench.bench.experiment import load_experiment
from vlocbench.cli import main
from vlocbench.loc.gallery import CameraModel, GalleryWriter
from vlocbench.locks import LOCK_FILE


def _plan(tmp_path, methods, name="e"):
    return load_experiment(
        {
            "name": name,
            "towns": ["town10"],
            "methods": methods,
            "output": str(tmp_path / name),
            "cache": str(tmp_path / "cache"),
        }
    )


def _gallery(folder):
    """A gallery of one tiny image."""
    camera = CameraModel(8, 6, np.array([[4.0, 0, 4], [0, 4.0, 3], [0, 0, 1]]))
    writer = GalleryWriter(folder)
    writer.add("0.png", np.zeros((6, 8, 3), np.uint8), "cam", camera, np.eye(4))
    return writer.close()


def _map(root, gallery, map_name, size=10):
    folder = root / "maps" / gallery.identity / map_name
    folder.mkdir(parents=True)
    (folder / "map.json").write_bytes(b"x" * size)
    return folder


@pytest.fixture
def filled(tmp_path):
    """A cache with the gallery and map an experiment uses, an old gallery with its map, a map of
    the used gallery's earlier content and a map of another method."""
    root = tmp_path / "cache"
    plan = _plan(tmp_path, ["sift"])
    sift = plan.map_name(plan.spec.methods[0])
    used_gallery = _gallery(root / "galleries" / plan.gallery_folder("town10"))
    used_map = _map(root, used_gallery, sift, size=1000)
    old_gallery = _gallery(root / "galleries" / "town10-0123456789")
    old_map = _map(root, old_gallery, sift)
    earlier = root / "maps" / f"{used_gallery.root.name}-feedfacefe" / sift
    earlier.mkdir(parents=True)
    xfeat = _plan(tmp_path, ["xfeat-lighterglue"], "x")
    other = _map(root, used_gallery, xfeat.map_name(xfeat.spec.methods[0]))
    return (
        root,
        plan,
        {
            "used": {used_gallery.root, used_map},
            "stale": {old_gallery.root, old_map, earlier, other},
        },
    )


def test_entries_and_what_an_experiment_uses(filled, tmp_path):
    root, plan, paths = filled
    found = cache.entries(root)
    assert [e.kind for e in found] == ["gallery"] * 2 + ["map"] * 4
    assert {e.name for e in found if e.kind == "gallery"} == {
        f"galleries/{plan.gallery_folder('town10')}",
        "galleries/town10-0123456789",
    }
    assert max(e.size_bytes for e in found if e.kind == "map") == 1000
    assert cache.used_by([plan], root) == {p.resolve() for p in paths["used"]}
    # the old gallery, its map, a map of the used gallery's earlier content, another method's map
    assert {e.path for e in cache.unused(root, [plan])} == paths["stale"]
    # an experiment in another cache keeps nothing here
    elsewhere = load_experiment({"name": "x", "towns": ["town10"], "methods": ["sift"]})
    assert len(cache.unused(root, [elsewhere])) == 6
    # the other method's map is in use once an experiment names that method
    both = _plan(tmp_path, ["sift", "xfeat-lighterglue"])
    assert len(cache.unused(root, [both])) == 3


def test_a_map_being_built_is_not_deleted(filled):
    root, plan, _ = filled
    entry = next(e for e in cache.unused(root, [plan]) if "xfeat" in e.name)
    with open(entry.path / LOCK_FILE, "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        assert not cache.delete(entry) and entry.path.exists()
    assert cache.delete(entry) and not entry.path.exists()


def test_cli_lists_marks_and_deletes_only_with_experiments_to_keep(filled, tmp_path, capsys):
    root, _, paths = filled
    experiment = tmp_path / "keep.yaml"
    experiment.write_text(
        json.dumps({"name": "e", "towns": ["town10"], "methods": ["sift"], "cache": str(root)})
    )
    assert main(["cache", "--cache", str(root)]) == 0
    out = capsys.readouterr().out
    assert "2 galleries, 4 maps" in out and "unused" not in out
    assert (
        "------------  galleries/town10-0123456789\n" in out
    )  # made before platforms were recorded
    assert main(["cache", "--cache", str(root), "--delete"]) == 1
    assert "--keep" in capsys.readouterr().err
    assert main(["cache", "--cache", str(tmp_path / "none")]) == 1
    assert "is not a folder" in capsys.readouterr().err
    assert main(["cache", "--cache", str(root), "--keep", str(experiment)]) == 0
    out = capsys.readouterr().out
    assert out.count("unused") == 4 and "--delete removes them" in out
    assert all(p.exists() for p in paths["stale"])
    assert main(["cache", "--cache", str(root), "--keep", str(experiment), "--delete"]) == 0
    assert "deleted 4" in capsys.readouterr().out
    assert not any(p.exists() for p in paths["stale"]) and all(p.exists() for p in paths["used"])
