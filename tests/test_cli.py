import os
import shutil
import signal
import subprocess
import sys
import time

import pytest
import yaml

from tests.conftest import assert_stops_cleanly
from vlocbench.cli import _signals_interrupt, build_parser, main


def test_map_writes_a_png(tmp_path, capsys):
    out = tmp_path / "town10.png"
    assert main(["map", "town10", "-o", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_unknown_town_is_a_clear_error(capsys):
    assert main(["map", "nowhere"]) == 1
    err = capsys.readouterr().err
    assert "unknown town 'nowhere'" in err and "town01" in err and "town10" in err


def test_bad_fov_names_the_field(capsys, tmp_path):
    assert main(["render", "town10", "--fov", "0", "-o", str(tmp_path / "x.png")]) == 1
    assert "fov_deg" in capsys.readouterr().err
    assert main(["render", "town10", "--deposits", "1.5", "-o", str(tmp_path / "x.png")]) == 1
    assert "weather.deposits: must be in [0, 1]" in capsys.readouterr().err


def test_render_with_and_without_antialiasing(tmp_path):
    import cv2
    import numpy as np

    size = ["--width", "160", "--height", "120", "--waypoint", "40"]
    assert main(["render", "town10", *size, "--antialias", "-o", str(tmp_path / "smooth.png")]) == 0
    assert main(["render", "town10", *size, "-o", str(tmp_path / "hard.png")]) == 0
    smooth, hard = (cv2.imread(str(tmp_path / f)).astype(int) for f in ("smooth.png", "hard.png"))
    changed = np.abs(smooth - hard).max(axis=2) > 10
    assert smooth.shape == (120, 160, 3) and 0 < changed.mean() < 0.1


def test_drive_prints_failure_rates(capsys, tmp_path):
    config = tmp_path / "episode.yaml"
    config.write_text("mode: ground_truth\nlocalization_rate_hz: 1.0\n")
    plot = tmp_path / "drive.png"
    assert (
        main(
            [
                "drive",
                "town10",
                "--localizer",
                "oracle",
                "--config",
                str(config),
                "--plot",
                str(plot),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "town10: route 489 m; oracle, ground_truth" in out
    assert "seed 0: 0 failures (0.0/km)" in out and "done" in out
    assert "failure rate F = 0.0 per km over 1 episodes" in out
    assert f"wrote {plot}" in out and plot.read_bytes()[:4] == b"\x89PNG"


def test_drive_rejects_unknown_localizers_and_bad_configs(capsys, tmp_path):
    assert main(["drive", "town10", "--localizer", "gps"]) == 1
    assert "unknown localizer 'gps'; valid: odometry, oracle, visual" in capsys.readouterr().err
    config = tmp_path / "episode.yaml"
    config.write_text("latency: {mode: sometimes}\n")
    assert main(["drive", "town10", "--config", str(config)]) == 1
    assert "valid: fixed, measured, none" in capsys.readouterr().err


def test_gallery_build_map_and_localize(tmp_path, capsys):
    import yaml

    from tests.conftest import small_spec
    from vlocbench.config import to_dict

    spec = tmp_path / "small.yaml"
    spec.write_text(yaml.safe_dump(to_dict(small_spec())))
    gallery, maps = tmp_path / "gallery", tmp_path / "map"
    args = ["--width", "320", "--height", "240", "--spacing", "4"]
    assert main(["gallery", "capture", str(spec), "--out", str(gallery), *args]) == 0
    assert "wrote" in capsys.readouterr().out
    assert main(["build-map", str(gallery), "--method", "sift", "--out", str(maps)]) == 0
    assert "points, mean track length" in capsys.readouterr().out
    import pycolmap

    # the gallery image the map saw best (scene 7's small town has bare views, e.g. 00008)
    sfm = pycolmap.Reconstruction(maps / "sfm")
    best = max(sfm.images.values(), key=lambda im: im.num_points3D)
    image = gallery / "images" / best.name
    assert main(["localize", str(image), "--map", str(maps)]) == 0
    out = capsys.readouterr().out
    assert "world_from_cam" in out and "inliers" in out
    assert (
        main(
            [
                "drive",
                str(spec),
                "--localizer",
                "visual",
                "--map",
                str(maps),
                "--mode",
                "ground_truth",
            ]
        )
        == 0
    )
    assert "seed 0: 0 failures" in capsys.readouterr().out
    assert main(["drive", str(spec), "--localizer", "visual"]) == 1
    assert "needs --map" in capsys.readouterr().err
    assert main(["build-map", str(gallery), "--method", "surf"]) == 1
    assert "unknown method 'surf'" in capsys.readouterr().err
    assert main(["build-map", str(gallery), "--min-track-length", "1"]) == 1
    assert "mapping.min_track_length: must be >= 2" in capsys.readouterr().err
    assert main(["localize", str(image), "--map", str(tmp_path / "none")]) == 1
    assert "not a map" in capsys.readouterr().err


def test_exit_codes_by_kind_of_error(capsys, tmp_path):
    import pytest

    with pytest.raises(SystemExit) as exc:  # the command line itself is wrong: usage, 2
        main(["drive", "town10", "--seeds", "0"])
    assert exc.value.code == 2
    assert "--seeds: must be at least 1, got 0" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["drive", "town10", "--colour", "red"])
    assert exc.value.code == 2
    assert main(["render", "town10", "--k", "11", "-o", str(tmp_path / "x.png")]) == 1  # input
    assert "illumination.k: must be in [0, 10], got 11" in capsys.readouterr().err
    assert main(["render", "town10", "--street-lights", "dusk", "-o", str(tmp_path / "x.png")]) == 1
    assert "street_lights.mode" in capsys.readouterr().err
    busy = tmp_path / "busy"
    from vlocbench.bench.store import ResultStore

    experiment = tmp_path / "exp.yaml"
    experiment.write_text("name: exp\ntowns: [town10]\nmethods: [sift]\n")
    with ResultStore(busy, "exp"):  # another run holds the folder: the machine's state, 3
        assert main(["run", str(experiment), "--output", str(busy), "--no-progress"]) == 3
        assert "in use by another vlocbench run" in capsys.readouterr().err
    assert main(["report", str(busy)]) == 1  # no run in it yet: input
    assert "has no run yet" in capsys.readouterr().err
    help_text = build_parser().format_help()
    assert "exit codes:" in help_text and "3  the machine stops it" in help_text


def test_run_part_of_an_experiment_names_what_it_lacks(capsys, tmp_path):
    experiment = "experiments/paper/illumination_reduced.yaml"
    out = ["--output", str(tmp_path / "out")]
    assert main(["run", experiment, "--methods", "sfit", *out]) == 1  # before any work
    assert "unknown method 'sfit'; valid: sift, xfeat-lighterglue" in capsys.readouterr().err
    assert main(["run", experiment, "--towns", "town02", *out]) == 1
    assert "unknown town 'town02'; valid: town01, town10" in capsys.readouterr().err
    assert main(["run", experiment, "--setup", "k=0", "--setup", "k=1", *out]) == 1
    assert "unknown setup 'k=1'; valid: illumination.k=0" in capsys.readouterr().err
    assert main(["run", experiment, "--repetitions", "9", *out]) == 1
    assert "repetitions: must be from 1 to the experiment's" in capsys.readouterr().err
    with pytest.raises(SystemExit, match="2"):  # a usage error, from argparse
        main(["run", experiment, "--methods", " , "])
    assert "expected comma-separated names, got none" in capsys.readouterr().err


def test_cli_run_and_report_errors(tiny, tmp_path, capsys):
    from vlocbench.cli import main

    root, _ = tiny
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        yaml.safe_dump({"towns": ["town10"], "methods": ["sift"], "sweep": {"weather.fogg": [10]}})
    )
    assert main(["run", str(bad)]) == 1
    assert (
        "valid: deposits, fog_model, fog_ramp_m, fog_visual_range_m, overcast, rain, rain_streaks_per_kpx, wetness"
        in (capsys.readouterr().err)
    )
    other = tmp_path / "other.yaml"
    other.write_text(
        yaml.safe_dump(
            {
                "towns": ["town10"],
                "baseline": True,
                "recall": False,
                "failure": False,
                "output": str(root / "out"),
            }
        )
    )
    assert main(["run", str(other), "--no-progress"]) == 1
    assert "holds results of experiment 'tiny', not 'other'" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:  # a malformed command line: usage, 2
        main(["run", str(other), "--workers", "0"])
    assert exc.value.code == 2
    assert "--workers: must be at least 1, got 0" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["build-map", str(tmp_path / "gallery"), "--workers", "0"])
    assert exc.value.code == 2
    assert "--workers: must be at least 1, got 0" in capsys.readouterr().err
    assert main(["report", str(tmp_path / "empty")]) == 1
    assert "holds no vlocbench results" in capsys.readouterr().err
    assert main(["report", str(root / "out"), "--no-examples"]) == 0
    out = capsys.readouterr().out
    assert "index.html" in out
    assert "small:\n| method | k=0 | k=6 |" in out  # the failure table, as a run prints it
    assert "episodes computed on one platform: 5 on " in out
    assert os.path.exists(root / "out" / "report" / "tables.md")
    # a part of the run again (all done: only its report), in a copy of the store
    shutil.copytree(root / "out", tmp_path / "copy")
    part = ["run", str(root / "tiny.yaml"), "--setup", "k=0", "--output", str(tmp_path / "copy")]
    assert main([*part, "--no-progress", "--no-examples"]) == 0
    out = capsys.readouterr().out
    assert "0 episodes run, 3 done before" in out
    assert f"--experiment {root / 'tiny.yaml'})" in out  # how to report the whole experiment
    # the same part into a new folder, its episodes taken from the first store
    fresh = [*part[:-1], str(tmp_path / "fresh"), "--no-progress", "--no-report"]
    assert main([*fresh, "--reuse", str(root / "out")]) == 0
    assert "0 episodes run, 3 done before (3 of them taken from other stores)" in (
        capsys.readouterr().out
    )
    assert main([*fresh, "--reuse", str(tmp_path / "empty")]) == 1
    assert f"{tmp_path / 'empty'} holds no vlocbench results" in capsys.readouterr().err
    # the noon part as an experiment of its own: the night's two episodes stay in the store, named
    noon = tmp_path / "noon.yaml"
    noon.write_text(
        yaml.safe_dump({**yaml.safe_load((root / "tiny.yaml").read_text()), "sweep": {}})
    )
    assert main(["report", str(tmp_path / "copy"), "--experiment", str(noon), "--no-examples"]) == 0
    out = capsys.readouterr().out
    assert "3 of the 3 episodes of tiny" in out
    assert f"2 more episodes in {tmp_path / 'copy'} are of other settings" in out


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_handled_inside_a_finalizer_still_interrupts(stop):
    """The garbage collector can run a finalizer just when the signal's handler runs; Python
    swallows an exception raised there. The command is interrupted all the same (a build-map in
    CI once ran to its end after a SIGTERM that landed in a weakref callback)."""

    class SignalledWhileFinalized:
        def __del__(self) -> None:
            signal.raise_signal(stop)  # runs the handler here, inside the finalizer

    with pytest.raises(KeyboardInterrupt, match=signal.Signals(stop).name), _signals_interrupt():
        obj = SignalledWhileFinalized()
        del obj
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:  # ordinary code, where the resent signal is handled
            time.sleep(0.001)
        pytest.fail("the signal was swallowed by the finalizer")


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM])
def test_build_map_stops_cleanly_on_a_signal_and_a_rerun_finishes(gallery, tmp_path, stop):
    """Sent while matching (pycolmap and OpenCV loaded): exit 130, no native stack trace, no map
    file; the same command again builds the map."""
    out = tmp_path / "map"
    cmd = [
        sys.executable,
        "-m",
        "vlocbench.cli",
        "build-map",
        str(gallery.root),
        "--method",
        "sift",
        "--out",
        str(out),
    ]
    # the build's matching and triangulation take about 0.6 s after the features' line: at the
    # lowest priority it does not run out of that window while this process sends the signal
    # from a loaded machine (CI once saw it finish first and exit 0)
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: os.nice(19),
    )
    for line in proc.stdout:  # the features are extracted: the native libraries are loaded
        if line.strip().startswith("matches") or ("features" in line and "/" in line):
            break
    assert "interrupted" in assert_stops_cleanly(proc, stop, 130)
    assert not (out / "map.json").exists()
    assert subprocess.run(cmd, capture_output=True, text=True, check=True).returncode == 0
    assert (out / "map.json").exists()


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM])
def test_gallery_capture_stops_cleanly_on_a_signal(tmp_path, stop):
    """Sent once images are being written (the renderer and pycolmap loaded): exit 130, no
    native stack trace, and no gallery index: the folder is not taken for a finished gallery."""
    out = tmp_path / "gallery"
    cmd = [
        sys.executable,
        "-m",
        "vlocbench.cli",
        "gallery",
        "capture",
        "town10",
        "--out",
        str(out),
        "--width",
        "160",
        "--height",
        "120",
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while len(list(out.glob("images/*"))) < 3:
        assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read()
        time.sleep(0.1)
    assert_stops_cleanly(proc, stop, 130)
    assert not (out / "gallery.json").exists()


def test_towns_lists_the_built_in_ones_and_generates_others(capsys, tmp_path):
    assert main(["towns"]) == 0
    assert "town01: town" in capsys.readouterr().out
    out = tmp_path / "maps"
    assert main(["towns", "--generate", "2", "--style", "city", "--seed", "3", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "gen-city-3-0: city" in printed and "route 500 m with 6 turns" in printed
    assert sorted(p.name for p in out.iterdir()) == ["gen-city-3-0.png", "gen-city-3-1.png"]
    assert main(["towns", "--generate", "2", "--style", "village", "-o", str(out)]) == 1
    assert "unknown style 'village'; valid: city, town" in capsys.readouterr().err


def test_platform_names_this_machine_and_what_a_store_ran_on(tiny, tmp_path, capsys):
    import json
    import sqlite3

    from vlocbench.bench.platform import current_platform
    from vlocbench.bench.store import DB_FILE

    root, _ = tiny
    here = current_platform()
    assert main(["platform", str(root / "out")]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"platform {here.id}\n  render   {here.render}  ")
    assert f"5 finished episodes\n       5 on {here.id} (this machine's)" in out
    # the failure drives as if run on a machine whose renderer draws otherwise
    shutil.copytree(root / "out", tmp_path / "copy")
    other = {**here.to_dict(), "id": "0123456789ab", "render": "f" * 16}
    with sqlite3.connect(tmp_path / "copy" / DB_FILE) as db:
        db.execute("UPDATE episodes SET platform = '0123456789ab' WHERE kind = 'failure'")
        db.execute("INSERT INTO platforms VALUES ('0123456789ab', ?)", (json.dumps(other),))
    assert main(["platform", str(tmp_path / "copy"), "--json"]) == 0
    out = capsys.readouterr().out
    assert json.loads(out[: out.index("\n}") + 2]) == json.loads(json.dumps(here.to_dict()))
    assert f"3 on {here.id} (this machine's)" in out
    assert "2 on 0123456789ab (not this machine's: ['render'])" in out
    assert main(["platform", str(tmp_path / "none")]) == 1  # not a store: named
    assert "holds no vlocbench results" in capsys.readouterr().err


def test_verify_drives_stored_episodes_again(tiny, capsys):
    root, _ = tiny
    args = ["--kinds", "baseline,failure", "--methods", "sift,odometry", "--count", "2"]
    assert main(["verify", str(root / "out"), *args]) == 0
    out = capsys.readouterr().out
    assert out.count(": the same to the last digit (") == 2
    assert out.endswith("2 of 2 the same to the last digit\n")
    assert main(["verify", str(root / "out"), "--kinds", "drive"]) == 1
    assert "--kinds: unknown episode kind 'drive'" in capsys.readouterr().err
