import dataclasses

import pytest

from vlocbench.bench.experiment import load_experiment, resolve
from vlocbench.errors import ConfigError, UnknownNameError


def _spec(**overrides):
    data = {"name": "t", "towns": ["town10"], "methods": ["sift"], "repetitions": 2}
    return load_experiment({**data, **overrides})


def test_sweep_is_a_cartesian_product_with_grouped_levels():
    spec = _spec(
        sweep={
            "illumination.k": [0, 3, 6],
            "viewpoint": [{"dz_m": 0, "pitch_down_deg": 0}, {"dz_m": 4, "pitch_down_deg": 22.5}],
            "season": "winter",  # a scalar: fixed, not an axis
        }
    )
    got = spec.setups
    assert len(got) == 6
    assert {s.conditions.season for s in got} == {"winter"}
    assert got[4].conditions.illumination.k == 6 and got[4].conditions.viewpoint.dz_m == 0
    assert got[5].conditions.viewpoint.pitch_down_deg == 22.5
    assert got[1].label == "illumination.k=0, viewpoint(dz_m=4, pitch_down_deg=22.5)"


def test_query_cameras_and_rigs_start_from_the_gallery_camera():
    spec = _spec(
        gallery={"camera": {"intrinsics": {"width": 320, "height": 240}}},
        sweep={"camera.extrinsics.yaw_deg": [-90, -60]},
    )
    cams = [s.cameras[0] for s in spec.setups]
    assert [c.extrinsics.yaw_deg for c in cams] == [-90, -60]
    assert {(c.intrinsics.width, c.extrinsics.z_m) for c in cams} == {(320, 2.0)}
    rig = _spec(
        sweep={
            "cameras": [
                [{"name": "r"}],
                [{"name": "r"}, {"name": "l", "extrinsics": {"yaw_deg": 90}}],
            ]
        }
    )
    assert [len(s.cameras) for s in rig.setups] == [1, 2]
    assert rig.setups[1].cameras[1].extrinsics.yaw_deg == 90


def test_expansion_counts_and_keys():
    spec = _spec(
        methods=[
            "sift",
            {"name": "orb", "features": "orb-teblid", "matcher": "nn-hamming", "retrieval": "vlad"},
        ],
        sweep={"illumination.k": [0, 6]},
    )
    tasks = spec.tasks()
    kinds = [t.kind for t in tasks]
    # per method and setup: 1 recall + 2 failure; the baseline renders nothing, so k does not
    # change it: one set of baselines serves both setups, of at least 10 seeds
    assert (
        kinds.count("recall") == 4 and kinds.count("failure") == 8 and kinds.count("baseline") == 10
    )
    assert sorted(t.episode.seed for t in tasks if t.kind == "baseline") == list(range(10))
    few = _spec(baseline_repetitions=1, recall=False, failure=False).tasks()
    assert len(few) == 2  # never fewer than the methods' repetitions
    assert len({t.key for t in tasks}) == len(tasks)
    assert {t.episode.mode for t in tasks if t.kind == "recall"} == {"ground_truth"}
    assert sorted({t.episode.seed for t in tasks if t.kind == "failure"}) == [0, 1]
    # the same spec gives the same keys; any change to what determines a result changes them
    assert [t.key for t in spec.tasks()] == [t.key for t in tasks]
    other = resolve(dataclasses.replace(spec.spec, seed=50)).tasks()
    assert not {t.key for t in other} & {t.key for t in tasks}
    latency = _spec(methods=["sift"], episode={"latency": {"mode": "none"}})
    base = _spec(methods=["sift"])
    assert not {t.key for t in latency.tasks()} & {t.key for t in base.tasks()}
    # traffic changes what the baseline drives through: then setups need their own baselines
    traffic = _spec(sweep={"traffic.cars": [0, 5]}, recall=False, failure=False)
    assert len(traffic.tasks()) == 20


def _method_keys(plan):
    return {t.key for t in plan.tasks() if t.method is not None}


def test_keys_name_what_makes_the_maps_not_where_they_lie():
    plan = _spec()
    # no map is needed to list the episodes; the runner binds each to its folder afterwards
    maps = {("town10", "sift"): "/cache/maps/town10-g-c/sift-1"}
    bound = [t.on_maps(maps) for t in plan.tasks()]
    assert {t.map_dir for t in bound if t.kind != "baseline"} == {maps[("town10", "sift")]}
    assert {t.map_dir for t in bound if t.kind == "baseline"} == {None}
    assert [t.key for t in bound] == [t.key for t in plan.tasks()]
    assert _method_keys(_spec(cache="/elsewhere", output="/other")) == _method_keys(plan)
    # the gallery's drive and the mapping settings make other maps: other episodes
    assert not _method_keys(_spec(gallery={"spacing_m": 3.0})) & _method_keys(plan)
    assert not _method_keys(_spec(mapping={"num_pairs": 10})) & _method_keys(plan)
    # the baseline renders nothing: no gallery or map of its own
    baselines = {t.key for t in plan.tasks() if t.kind == "baseline"}
    assert baselines == {
        t.key for t in _spec(gallery={"spacing_m": 3.0}).tasks() if t.kind == "baseline"
    }


def test_part_of_a_plan_keeps_its_episode_keys():
    whole = _spec(
        towns=["town01", "town10"],
        sweep={"illumination.k": [0, 6]},
        methods=[
            "sift",
            {"name": "orb", "features": "orb-teblid", "matcher": "nn-hamming", "retrieval": "vlad"},
        ],
    )
    part = whole.only(towns=["town10"], methods=["orb"])
    assert part.spec.towns == ("town10",) and [m.name for m in part.spec.methods] == ["orb"]
    keys = {t.key: t for t in whole.tasks()}
    tasks = part.tasks()
    assert tasks and all(t.key in keys and t.town == "town10" for t in tasks)
    assert {t.method.name for t in tasks if t.method} == {"orb"}
    assert whole.only().tasks() == whole.tasks()
    with pytest.raises(UnknownNameError, match="valid: orb, sift"):
        whole.only(methods=["sift-gem"])
    with pytest.raises(UnknownNameError, match="unknown town 'town02'; valid: town01, town10"):
        whole.only(towns=["town02"])
    drives = whole.only(methods=["sift"], kinds=["recall", "baseline"]).tasks()
    assert {t.kind for t in drives} == {"recall", "baseline"}
    assert {t.key for t in drives} == {
        t.key
        for t in whole.tasks()
        if t.kind == "baseline" or (t.method_name == "sift" and t.kind == "recall")
    }
    with pytest.raises(UnknownNameError, match="valid: baseline, failure, recall"):
        whole.only(kinds=["recalls"])
    with pytest.raises(UnknownNameError, match="unknown episode kind 'baseline'"):
        whole.only(kinds=["recall"]).only(kinds=["baseline"])  # not in the part
    # a setup of the sweep, by its label or without the key's first part
    night = whole.only(setups=["k=6"])
    assert night.setups == whole.only(setups=["illumination.k=6"]).setups
    assert [x.label for x in night.setups] == ["illumination.k=6"]
    assert {t.key for t in night.tasks()} == {
        t.key for t in whole.tasks() if t.setup.label == "illumination.k=6" or t.kind == "baseline"
    }
    with pytest.raises(UnknownNameError, match=r"unknown setup 'k=3'; valid: illumination\.k=0"):
        whole.only(setups=["k=3"])


def test_the_first_repetitions_of_a_plan_keep_their_keys():
    whole = _spec(repetitions=3, baseline_repetitions=10)
    keys = {t.key: t for t in whole.tasks()}
    first = whole.only(repetitions=2).tasks()
    assert all(t.key in keys for t in first)
    # each method's recall drive, its first 2 failure drives, the odometry line's first 2
    assert sorted((t.kind, t.repetition) for t in first) == sorted(
        (t.kind, t.repetition) for t in keys.values() if t.repetition < 2
    )
    assert sum(t.kind == "baseline" for t in first) == 2
    # all of a method's repetitions: the odometry line cut to as many
    assert whole.only(repetitions=3).tasks() == [
        t for t in whole.tasks() if t.kind != "baseline" or t.repetition < 3
    ]
    with pytest.raises(
        ConfigError, match="repetitions: must be from 1 to the experiment's 3, got 4"
    ):
        whole.only(repetitions=4)


def test_a_grouped_level_is_chosen_by_its_label_or_its_fields():
    whole = _spec(
        sweep={
            "viewpoint": [
                {"dz_m": 0, "pitch_down_deg": 0},
                {"dz_m": 4, "pitch_down_deg": 22.5},
                {"dz_m": 8, "pitch_down_deg": 37.5},
            ]
        }
    )
    label = "viewpoint(dz_m=4, pitch_down_deg=22.5)"
    part = whole.only(setups=["dz_m=4, pitch_down_deg=22.5"])
    assert [x.label for x in part.setups] == [label]
    assert whole.only(setups=[label]).setups == part.setups
    # a value's decimal point is no key's: "5)" named no setup, and no listed one is a fragment
    with pytest.raises(UnknownNameError, match=r"valid: dz_m=0, pitch_down_deg=0; dz_m=4, ") as err:
        whole.only(setups=["5)"])
    assert err.value.valid == sorted(
        [*(x.label for x in whole.setups), *(x.label[10:-1] for x in whole.setups)]
    )


def test_episode_settings_sweep_as_setups():
    plan = _spec(sweep={"episode.ekf.late_measurements": ["current", "replay"]})
    assert [s.episode.ekf.late_measurements for s in plan.setups] == ["current", "replay"]
    assert plan.setups[1].label == "episode.ekf.late_measurements=replay"
    assert plan.axis == ("episode.ekf.late_measurements",)
    tasks = plan.tasks()
    keys = [{t.key for t in tasks if t.setup == s} for s in plan.setups]
    assert not keys[0] & keys[1]  # the baseline too: its EKF is part of what it drives with
    assert {t.episode.ekf.late_measurements for t in tasks if t.setup == plan.setups[1]} == {
        "replay"
    }
    # a fixed value equal to the default changes no key
    fixed = _spec(sweep={"episode.ekf.late_measurements": "current"})
    assert {t.key for t in fixed.tasks()} == {t.key for t in _spec().tasks()}
    with pytest.raises(ConfigError, match=r"sweep\.episode\.seed: is set per episode"):
        _spec(sweep={"episode.seed": [1, 2]})
    with pytest.raises(UnknownNameError, match="valid: current, replay"):
        _spec(sweep={"episode.ekf.late_measurements": ["sometimes"]})


def test_bad_experiments_are_clear_errors(tmp_path):
    with pytest.raises(
        UnknownNameError,
        match="valid: gen-STYLE-SEED-INDEX, hidden-DIGEST-STYLE-INDEX, town01, town10",
    ):
        _spec(towns=["town99"])
    with pytest.raises(UnknownNameError, match=r"valid: aliked-lightglue, .*sift"):
        _spec(methods=["surf"])
    with pytest.raises(UnknownNameError, match=r"sweep key 'illumnation\.k'; valid: camera"):
        _spec(sweep={"illumnation.k": [1]})
    with pytest.raises(
        UnknownNameError,
        match="illumination: unknown key 'kk'; valid: cloud_cover, k, sun_azimuth_deg",
    ):
        _spec(sweep={"illumination.kk": [1]})
    with pytest.raises(
        ConfigError, match=r"sweep\.illumination\.k: an empty list expands to zero runs"
    ):
        _spec(sweep={"illumination.k": []})
    with pytest.raises(ConfigError, match=r"sweep\.illumination\.k: must be in \[0, 10\], got -2"):
        _spec(sweep={"illumination.k": [0, -2]})
    with pytest.raises(UnknownNameError, match="season"):
        _spec(sweep={"season": ["summer", "monsoon"]})
    with pytest.raises(ConfigError, match="repetitions: must be >= 1"):
        _spec(repetitions=0)
    with pytest.raises(ConfigError, match="baseline_repetitions: must be >= 1"):
        _spec(baseline_repetitions=0)
    with pytest.raises(
        ConfigError, match=r"route_length_m: 99999 m is longer than town10's route \(489 m\)"
    ):
        _spec(route_length_m=99999)
    with pytest.raises(ConfigError, match="methods: recall and failure episodes need"):
        _spec(methods=[])
    with pytest.raises(
        UnknownNameError, match="'sed'; valid: baseline, baseline_repetitions, cache"
    ):
        _spec(sed=1)
    with pytest.raises(ConfigError, match="give all of features, matcher and retrieval"):
        _spec(methods=[{"name": "mine", "features": "sift"}])
    with pytest.raises(ConfigError, match=r"gallery\.camera\.antialias: expected true or false"):
        _spec(gallery={"camera": {"antialias": "maybe"}})
    bad = tmp_path / "bad.yaml"
    bad.write_text("towns: [town10\n")
    with pytest.raises(ConfigError, match="invalid YAML"):
        load_experiment(bad)


def test_shipped_experiments_load():
    from pathlib import Path

    root = Path(__file__).parents[2].joinpath("experiments")
    files = sorted(root.glob("*.yaml"))
    names = {f.stem for f in files}
    assert {
        "smoke",
        "demo",
        "season",
        "intrinsics",
        "extrinsics",
        "multi_camera",
        "traffic",
        "headlights",
        "night_retrieval",
        "antialiased",
    } <= names
    for f in files:
        spec = load_experiment(f)
        assert spec.name == f.stem and spec.setups
    # the paper's three at its scale (the reduced illumination run shares the full one's store)
    paper = {f.stem: load_experiment(f) for f in sorted(root.joinpath("paper").glob("*.yaml"))}
    assert set(paper) == {"illumination", "illumination_reduced", "viewpoint", "weather"}
    assert len(paper["illumination"].setups) == 11 and paper["illumination"].spec.repetitions == 5
    assert len(paper["viewpoint"].setups) == 13 and len(paper["weather"].setups) == 4
    calibration = {f.stem for f in root.joinpath("calibration").glob("*.yaml")}
    assert {"rain"} <= calibration
    for name in calibration:
        load_experiment(root / "calibration" / f"{name}.yaml")
    full, reduced = paper["illumination"], paper["illumination_reduced"]
    assert (reduced.name, reduced.output_dir) == (full.name, full.output_dir)
    assert {s.label for s in reduced.setups} < {s.label for s in full.setups}


def test_episode_keys_are_stable():
    """Stored results are found by key: a refactoring must not change the keys of the paper's
    experiments (a deliberate change bumps EPISODE_VERSION and this digest with it)."""
    import hashlib

    spec = load_experiment("experiments/paper/illumination_reduced.yaml")
    keys = sorted(t.key for t in spec.tasks())
    assert len(keys) == 116
    # 2026-12-07: EPISODE_VERSION 9, the town's edge a wall (every episode re-keyed)
    assert hashlib.sha1(" ".join(keys).encode()).hexdigest()[:12] == "15b008b16756"


def test_a_ros_node_is_a_method_without_a_map():
    plan = _spec(
        methods=[
            "sift",
            {"name": "my-node", "kind": "ros", "args": {"image_topic": "cam", "timeout_s": 5}},
        ],
    )
    node = plan.spec.methods[1]
    assert not node.needs_map and node.args["image_topic"] == "cam"
    maps = {("town10", "sift"): "/cache/maps/g1/sift-1"}  # none for the node
    tasks = [t.on_maps(maps) for t in plan.tasks()]
    assert {t.map_dir for t in tasks if t.method_name == "my-node"} == {None}
    # an option added later changes no key of the methods that do not use it
    assert {t.key for t in tasks if t.method_name == "sift"} <= {t.key for t in _spec().tasks()}
    # a built-in kind's arguments are checked as the file is read, named by method and field
    with pytest.raises(ConfigError, match=r"methods\.n\.args\.ros\.timeout_s: must be > 0"):
        _spec(methods=[{"name": "n", "kind": "ros", "args": {"timeout_s": 0}}])
    with pytest.raises(ConfigError, match=r"ros\.pose_topic: must not be empty"):
        _spec(methods=[{"name": "n", "kind": "ros", "args": {"pose_topic": ""}}])
    with pytest.raises(ConfigError, match="kind ros takes no features, matcher"):
        _spec(
            methods=[
                {
                    "name": "n",
                    "features": "sift",
                    "matcher": "nn-ratio",
                    "retrieval": "vlad",
                    "kind": "ros",
                }
            ]
        )


def test_generated_sets_expand_into_towns_with_their_own_keys():
    plan = _spec(
        towns=["town10", {"generate": {"count": 3, "seed": 11, "style": "city"}}], recall=False
    )
    assert plan.spec.towns == ("town10", "gen-city-11-0", "gen-city-11-1", "gen-city-11-2")
    keys = {t.town: t.key for t in plan.tasks() if t.kind == "failure" and t.repetition == 0}
    assert len(set(keys.values())) == 4
    assert len({plan.gallery_key(t) for t in plan.spec.towns}) == 4
    with pytest.raises(ConfigError, match=r"towns\[0\].generate.count: must be in \[1, 64\]"):
        _spec(towns=[{"generate": {"count": 100}}])
    with pytest.raises(UnknownNameError, match="valid: gen-STYLE-SEED-INDEX, hidden-DIGEST"):
        _spec(towns=["town99"])


def test_the_place_revision_keys_only_episodes_of_a_camera_mounted_otherwise(monkeypatch):
    """Where a retrieved image's place is scored from changed in revision 2 for a query camera
    mounted otherwise than the gallery's: those episodes got new keys, the others kept theirs."""
    from vlocbench.bench import experiment

    def keys():
        plan = _spec(
            methods=["sift", {"name": "oracle", "kind": "oracle"}],
            sweep={
                "viewpoint": [{"dz_m": 0, "pitch_down_deg": 0}, {"dz_m": 4, "pitch_down_deg": 22.5}]
            },
        )
        turned = _spec(sweep={"camera.extrinsics.yaw_deg": [-90, -60]})
        return {
            (t.setup.label, t.method_name, t.kind, t.repetition): t.key for t in plan.tasks()
        }, {t.setup.label: t.key for t in turned.tasks() if t.kind == "recall"}

    before, turned_before = keys()
    monkeypatch.setattr(experiment, "PLACE_REVISION", 3)
    after, turned_after = keys()
    raised = "viewpoint(dz_m=4, pitch_down_deg=22.5)"
    # the map method's episodes of the raised camera; not the oracle's, not odometry's
    assert {c for c in before if before[c] != after[c]} == {
        c for c in before if c[0] == raised and c[1] == "sift"
    }
    yaw = "camera.extrinsics.yaw_deg="
    assert turned_before[yaw + "-90"] == turned_after[yaw + "-90"]
    assert turned_before[yaw + "-60"] != turned_after[yaw + "-60"]


def test_a_query_camera_with_another_tone_curve_than_the_gallerys_is_said():
    base = {"name": "x", "towns": ["town10"], "methods": ["sift"]}
    swept = load_experiment({**base, "sweep": {"exposure.tone_curve": ["gamma", "filmic"]}})
    (said,) = swept.camera_mismatches()
    assert said.startswith("setup exposure.tone_curve=filmic: its queries go through the filmic")
    assert "gallery: {conditions: {exposure: {tone_curve: filmic}}}" in said
    one_camera = {"conditions": {"exposure": {"tone_curve": "filmic"}}}
    same = {**base, "gallery": one_camera, "sweep": {"exposure.tone_curve": ["filmic"]}}
    assert load_experiment(same).camera_mismatches() == []
    assert load_experiment(base).camera_mismatches() == []


def test_one_keys_level_names_every_setup_at_it():
    whole = _spec(
        sweep={"illumination.k": [8, 10], "episode.ekf.late_measurements": ["current", "replay"]}
    )
    night = whole.only(setups=["k=8"])
    assert [x.label for x in night.setups] == [
        "illumination.k=8, episode.ekf.late_measurements=current",
        "illumination.k=8, episode.ekf.late_measurements=replay",
    ]
    assert whole.only(setups=["illumination.k=8"]).setups == night.setups
    replayed = whole.only(setups=["episode.ekf.late_measurements=replay"]).setups
    assert [x.levels for x in replayed] == [
        (("illumination.k", k), ("episode.ekf.late_measurements", "replay")) for k in (8, 10)
    ]
    # a whole label still names its one setup; names given together are their union
    one = "k=10, episode.ekf.late_measurements=current"
    assert [x.label for x in whole.only(setups=[one]).setups] == [f"illumination.{one}"]
    assert len(whole.only(setups=["k=8", one]).setups) == 3
    with pytest.raises(UnknownNameError, match="unknown setup 'k=9'; valid: "):
        whole.only(setups=["k=9"])
