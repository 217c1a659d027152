"""The shared real-data folder is found (CI sets OARAIM_REQUIRE_DATA=1, so this cannot skip)."""

import pytest

from oaraim.data import DataUnavailable, data_dir


def test_shared_data_folder_has_the_documented_files(shared_data):
    for rel in ("README.md", "nav/brdc1820.10n", "orbits/igs15904.sp3", "almanac/almmops.txt",
                "obs/07590920.05o"):
        assert (shared_data / rel).is_file(), rel


def test_oaraim_data_pointing_nowhere_is_a_clear_error(monkeypatch, tmp_path):
    monkeypatch.setenv("OARAIM_DATA", str(tmp_path / "missing"))
    with pytest.raises(DataUnavailable, match="OARAIM_DATA=.*neither a folder nor"):
        data_dir()
