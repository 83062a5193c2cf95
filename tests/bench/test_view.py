"""An episode as a rerun recording."""

import pytest

from vlocbench.bench.store import ResultStore


def test_an_episode_as_a_rerun_recording_reads_back(tiny, tmp_path, capsys):
    pytest.importorskip("rerun")
    from rerun.chunk import RrdReader

    from vlocbench.bench.store import read_episode_table
    from vlocbench.cli import main

    root, _ = tiny
    out = root / "out"
    path = tmp_path / "drive.rrd"
    args = ["view", str(out), "--setup", "k=6", "--method", "sift", "--images"]
    assert main([*args, "--out", str(path)]) == 0
    assert "failure drive" in capsys.readouterr().out  # failure drives first
    rows: dict[str, int] = {}
    for chunk in RrdReader(path).stream().collect().stream():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    with ResultStore(out, "tiny") as store:
        [row] = [r for r in store.rows() if r.kind == "failure" and r.setup.endswith("k=6")]
    locs = read_episode_table(out, row.key, "localizations")
    steps = len(read_episode_table(out, row.key, "trajectory")["time_s"])
    assert rows["/localization/log"] == len(locs["time_s"])  # every query, answered or not
    assert rows["/localization/camera"] == int(locs["success"].sum())  # a frustum per answer
    assert rows["/localization/camera/image"] == len(locs["time_s"])
    assert rows["/retrieved/0"] == len(locs["time_s"])
    assert rows["/truth"] == rows["/ekf"] == steps
    assert {"/town/buildings", "/route", "/truth/path", "/ekf/path"} <= set(rows)
    assert main(["view", str(out), "--method", "nope"]) == 1
    assert "there are: " in capsys.readouterr().err
    assert main(["view", str(out), "--episode", row.key]) == 0  # to OUTPUT/view/KEY.rrd
    from vlocbench.bench.report import write_report

    page = write_report(out, examples=False).html.read_text()
    assert f'<a href="../view/{row.key}.rrd">' in page and "failure drive, small, sift" in page
