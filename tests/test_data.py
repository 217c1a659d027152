"""The tests' data fixture gets every registry file (CI sets OARAIM_REQUIRE_DATA=1, so this
cannot skip there); tests/test_data_fetch.py runs it against a loopback mirror."""

import pytest

from oaraim import data
from oaraim.data import DataUnavailable, data_dir


def test_shared_data_holds_every_registry_file_verified(shared_data):
    """Each registry file is at its name in the fixture's folder and is the published file."""
    for name, e in data.registry().items():
        assert (shared_data / name).is_file(), name
        assert (shared_data / name).stat().st_size == e.size, name
        assert data.sha256(shared_data / name) == e.sha256, name


def test_oaraim_data_pointing_nowhere_is_a_clear_error(monkeypatch, tmp_path):
    monkeypatch.setenv("OARAIM_DATA", str(tmp_path / "missing"))
    with pytest.raises(DataUnavailable, match="OARAIM_DATA=.*neither a folder nor"):
        data_dir()
