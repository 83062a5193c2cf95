import pytest

from tests.bench.fakes import CONTROL_ENV


@pytest.fixture
def control(tmp_path, monkeypatch):
    folder = tmp_path / "control"
    folder.mkdir()
    monkeypatch.setenv(CONTROL_ENV, str(folder))
    return folder
