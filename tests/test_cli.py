"""The oaraim command line as a user meets it: errors exit 2 with one line, no traceback."""

import pytest
from typer.testing import CliRunner

from oaraim.studies.cli import app

runner = CliRunner()


def _run(*args):
    return runner.invoke(app, list(args), catch_exceptions=False)


def _one_error_line(result):
    text = result.output.strip()
    assert "Traceback" not in text
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1, text
    return lines[0]


def test_bad_probability_names_field_and_range():
    r = _run("run", "seed001-fig4-hpl-cdf", "--set", "p_md=2", "--no-progress")
    assert r.exit_code == 2
    line = _one_error_line(r)
    assert "p_md" in line and "(0, 1)" in line and "2" in line


def test_unknown_study_lists_known_ones():
    r = _run("run", "seed001-fig9", "--no-progress")
    assert r.exit_code == 2
    line = _one_error_line(r)
    assert "seed001-fig9" in line
    assert "seed001-fig3-elevation" in line and "seed001-fig4-hpl-cdf" in line


def test_unknown_set_key_lists_valid_keys():
    r = _run("run", "seed001-fig3-elevation", "--set", "n_sats=5", "--no-progress")
    assert r.exit_code == 2
    line = _one_error_line(r)
    assert "n_sats" in line and "n_gps" in line and "mask_deg" in line


@pytest.mark.parametrize("setting, field", [("d_min_m=4000", "d_min_m"), ("sigma_sop_m=-1",
                                            "sigma_sop_m"), ("n_gps=abc", "n_gps"),
                                            ("mask_deg=95", "mask_deg"), ("p_fa", "--set")])
def test_other_bad_inputs(setting, field):
    r = _run("run", "seed001-fig4-hpl-cdf", "--set", setting, "--no-progress")
    assert r.exit_code == 2
    assert field in _one_error_line(r)


def test_list_shows_studies_and_parameters():
    r = _run("list")
    assert r.exit_code == 0
    assert "seed001-fig3-elevation" in r.output and "--set p_md=0.001" in r.output


def test_list_prints_every_help_text_literally():
    """Issue 30: help texts are not Rich markup ("towers within [d_min_m, d_max_m] of a user"
    lost its brackets): every study's title and every parameter's text appear verbatim
    (whitespace folded, as the console wraps)."""
    from oaraim.studies.registry import STUDIES

    fold = lambda x: " ".join(x.split())  # noqa: E731
    text = fold(_run("list").output)
    assert "[d_min_m, d_max_m]" in text
    for name, s in STUDIES.items():
        assert fold(s.title) in text, name
        for key, p in s.params.items():
            assert fold(p.doc) in text, (name, key)


def test_run_then_report(tmp_path):
    r = _run("run", "seed001-fig4-hpl-cdf", "--realizations", "1500", "--out", str(tmp_path),
             "--no-progress")
    assert r.exit_code == 0, r.output
    assert "availability at HAL = 30 m" in r.output
    r = _run("report", "--out", str(tmp_path), "--write", str(tmp_path / "REPORT.md"))
    assert r.exit_code == 0
    assert "81.4" in r.output and "94.7" in r.output and "46" in r.output
    assert (tmp_path / "REPORT.md").read_text().startswith("# Reproduction report")


def test_report_without_results_is_a_clear_error(tmp_path):
    r = _run("report", "--out", str(tmp_path))
    assert r.exit_code == 2
    assert "no study results" in _one_error_line(r)
