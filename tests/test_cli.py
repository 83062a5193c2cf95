from vlocbench.cli import main


def test_map_writes_a_png(tmp_path, capsys):
    out = tmp_path / "town10.png"
    assert main(["map", "town10", "-o", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_unknown_town_is_a_clear_error(capsys):
    assert main(["map", "nowhere"]) == 2
    err = capsys.readouterr().err
    assert "unknown town 'nowhere'" in err and "town01" in err and "town10" in err


def test_bad_fov_names_the_field(capsys, tmp_path):
    assert main(["render", "town10", "--fov", "0", "-o", str(tmp_path / "x.png")]) == 2
    assert "fov_deg" in capsys.readouterr().err
