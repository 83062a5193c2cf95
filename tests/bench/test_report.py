"""Reports: a real run's page, and a sweep stored in parts reported whole."""

import dataclasses
import html

import yaml

from tests.bench.fakes import ILL_SPEC, run_fake_plans
from vlocbench.bench.experiment import load_experiment


def test_report_of_a_run(tiny):
    from vlocbench.bench.platform import current_platform
    from vlocbench.bench.report import platforms_line, write_report

    root, _ = tiny
    files = write_report(root / "out")
    md = files.markdown.read_text()
    assert "| sift |" in md and "| odometry only |" in md and "k=6" in md
    assert "place recognition alone" in md and "| sift | 25 m |" in md
    assert "/km) |" in md  # the fused recall with the EKF's lock losses in the ground-truth drive
    assert r"\begin{tabular}" in files.latex.read_text()
    assert {p.name for p in files.figures} == {
        "failure_rate_small.png",
        "failure_sites_small.png",
        "failure_vs_recall.png",
        "computation_time.png",
        "confidence_small.png",
    }
    assert "can the answers' confidence be trusted" in md and "| sift | k=0 | inliers |" in md
    assert "small: verdict, over illumination.k" in md
    page = files.html.read_text()
    assert page.count("data:image/png;base64,") == 5
    assert page.count("data:image/jpeg;base64,") == 4  # query and gallery view per setup
    assert 'src="http' not in page  # self-contained
    # which platform drew and computed the episodes; a warning where a store mixes several
    here = current_platform()
    assert files.platforms.startswith(f"episodes computed on one platform: 5 on {here.id} (")
    assert here.details["gl_renderer"] in files.platforms and html.escape(files.platforms) in page
    assert files.platforms.endswith("; their maps and galleries made on the same platform")
    label = files.platforms.split(" on ", 2)[2].split("; their")[0]  # id (driver; CPU; torch)
    mixed = dataclasses.replace(files.summary, platforms={here.id: 3, "0123456789ab": 1, None: 1})
    line = platforms_line(mixed, {here.id: here.to_dict()})
    assert line.startswith("WARNING: episodes computed on 2 platforms")
    assert line.endswith(
        f"3 on {label}; 1 on 0123456789ab (?; ?); 1 stored before platforms were recorded"
    )
    # a map made elsewhere, on a gallery made here, and a map from before they were recorded
    elsewhere = {"id": "fedcba987654", "details": {"gl_renderer": "NVIDIA H100", "cpu": "Xeon"}}
    maps = [{"made_on": elsewhere, "gallery": "g", "gallery_made_on": here.to_dict()}, {}]
    line = platforms_line(dataclasses.replace(files.summary, platforms={here.id: 5}), {}, maps)
    assert line.endswith(
        "; their maps made 1 on fedcba987654 (NVIDIA H100; Xeon), 1 before it was recorded"
        f"; their galleries made 1 on {label}, 1 before it was recorded"
    )


def test_a_sweep_run_in_parts_is_reported_whole(tmp_path, capsys):
    """A sweep run a level at a time (as on a small machine): the latest run's report shows its
    level, the experiment's report every level; episodes from another gallery do not count."""
    from vlocbench.bench.report import write_report
    from vlocbench.cli import main

    whole = {**ILL_SPEC, "sweep": {"illumination.k": [0, 6]}}
    (tmp_path / "ill.yaml").write_text(yaml.safe_dump(whole))
    parts = [load_experiment({**ILL_SPEC, "sweep": {"illumination.k": [k]}}) for k in (6, 0)]
    other_gallery = load_experiment({**whole, "gallery": {"spacing_m": 4.0}})
    run_fake_plans(tmp_path, other_gallery, *parts)
    latest = write_report(tmp_path, examples=False).summary
    assert [s.label for s in latest.setups] == ["default"] and latest.episodes == 3

    plan = load_experiment(tmp_path / "ill.yaml")
    files = write_report(tmp_path, examples=False, plan=plan)
    summary, planned = files.summary, plan.tasks()
    assert summary.episodes == summary.planned == len(planned) == 5  # (recall, failure) x 2, base
    for label in ("illumination.k=0", "illumination.k=6"):
        cell = summary.cell("town10", "sift", label)
        assert cell is not None and cell.failure is not None and cell.recall is not None, label
        assert cell.keys <= {t.key for t in planned}  # none of the other gallery's
    assert "5 of 5 episodes" in files.html.read_text()
    # the paper's illumination curves of town10 and ours in the same axes: F, and T1 recall
    for name in ("failure_rate_town10_paper.png", "recall_town10_paper.png"):
        beside = files.html.parent / name
        assert beside in files.figures and beside.read_bytes()[:4] == b"\x89PNG"

    assert (
        main(["report", str(tmp_path), "--experiment", str(tmp_path / "ill.yaml"), "--no-examples"])
        == 0
    )
    assert "5 of the 5 episodes of ill" in capsys.readouterr().out
    (tmp_path / "t01.yaml").write_text(yaml.safe_dump({**whole, "towns": ["town01"]}))
    assert main(["report", str(tmp_path), "--experiment", str(tmp_path / "t01.yaml")]) == 1
    assert "holds no episode of experiment 'ill'" in capsys.readouterr().err


def test_a_sweep_stored_in_part_has_a_verdict_over_its_stored_levels(tmp_path):
    """Three levels planned, the easiest and the hardest run (as the paper's six of eleven): the
    verdict reads over those two, and the odometry line is crossed nowhere (the fakes' sift
    fails at most once, odometry three times); without the odometry line stored, unknown."""
    from vlocbench.bench.report import write_report

    whole = load_experiment({**ILL_SPEC, "sweep": {"illumination.k": [0, 6, 8]}})
    for folder, baseline, crossed in (("with", True, "never"), ("without", False, "–")):
        parts = {**ILL_SPEC, "sweep": {"illumination.k": [0, 8]}, "baseline": baseline}
        run_fake_plans(tmp_path / folder, load_experiment(parts))
        md = write_report(tmp_path / folder, examples=False, plan=whole).markdown.read_text()
        verdict = md.split("verdict, over illumination.k")[1].split("\n\n**")[0]
        assert f"| sift | k=8 | {crossed} |" in verdict, folder


def test_a_cell_with_fewer_repetitions_than_planned_says_how_many(tmp_path):
    """Two repetitions planned (three of the odometry line), one run: the failure table gives
    each cell's count beside its F, and its caption the plan's."""
    from vlocbench.bench.report import write_report

    whole = load_experiment({**ILL_SPEC, "repetitions": 2, "baseline_repetitions": 3})
    run_fake_plans(tmp_path, whole.only(repetitions=1))
    md = write_report(tmp_path, examples=False, plan=whole).markdown.read_text()
    caption, table = md.split("failure rate F (failures/km")[1].split("\n\n", 1)
    assert "over 2 repetitions, odometry only over 3;" in caption
    rows = table.split("\n\n**")[0]
    assert "| sift |" in rows and "(1 of 2) |" in rows.split("| sift |")[1].split("\n")[0]
    assert "(1 of 3) |" in rows.split("| odometry only |")[1].split("\n")[0]
    run_fake_plans(tmp_path, whole)  # the rest: counts no longer shown
    md = write_report(tmp_path, examples=False, plan=whole).markdown.read_text()
    assert " of 2)" not in md and " of 3)" not in md


def test_a_numeric_key_swept_with_others_is_the_figures_x_axis(tmp_path):
    """F against k with a line per level of the other swept key (the filter's handling of late
    answers), the odometry line as well; a sweep of one non-numeric key: a tick per setup."""
    from vlocbench.bench.report import write_report
    from vlocbench.bench.report.figures import figure_series

    late = "episode.ekf.late_measurements"
    plan = load_experiment(
        {**ILL_SPEC, "sweep": {"illumination.k": [0, 6], late: ["current", "replay"]}}
    )
    run_fake_plans(tmp_path, plan)
    files = write_report(tmp_path, examples=False, plan=plan)
    series = figure_series(files.summary)
    assert series.x == [0.0, 6.0] and series.ticks == ["0", "6"]
    assert series.xlabel == "illumination.k"
    assert series.lines == [
        (f"late_measurements={v}", [f"illumination.k={k}, {late}={v}" for k in (0, 6)])
        for v in ("current", "replay")
    ]
    assert (files.html.parent / "failure_rate_town10.png") in files.figures
    only_late = load_experiment({**ILL_SPEC, "sweep": {late: ["current", "replay"]}})
    run_fake_plans(tmp_path / "late", only_late)
    one = figure_series(write_report(tmp_path / "late", examples=False, plan=only_late).summary)
    assert one.x == [0, 1] and one.lines == [("", [f"{late}=current", f"{late}=replay"])]
    assert one.ticks == ["late_measurements=current", "late_measurements=replay"]
