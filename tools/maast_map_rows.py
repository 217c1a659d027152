"""Per-point parity of the availability map with MAAST for ARAIM 2's user algorithm.

    python tools/maast_map_rows.py export LAT [LAT ...]   # writes /tmp/maast_rows/*.txt
    octave-cli --eval "addpath('/path/to/maast_for_araim_2'); run('tools/maast_map_rows.m')"
    python tools/maast_map_rows.py compare OUT            # OUT: an availability-map run
    python tools/maast_map_rows.py fixture OPT.txt NOOPT.txt EVERY   # tests/data fixture

``export`` computes the map's own inputs (sky, elevation mask, C_int, C_acc, b_nom, P_sat) for
every user-epoch of the given latitude rows, with the map's default parameters, and writes them
as text for ``maast_map_rows.m``, which runs MAAST's ``usr_vhpl_araim`` (LPV-200, MAAST's
trigger and keep rule of the position optimisation, ``fast`` on, no FDE, no exposure, N_es 1:
the map's budget) on them. ``compare`` reads MAAST's VPL, HPL, EMT and sigma_acc back and
compares them with the run in OUT (``--set lat_deg=LAT,...``, the same other parameters).
MAAST's code is not part of this project; the .m driver only calls it.
"""

import json
import sys
from pathlib import Path

import numpy as np

DIR = Path("/tmp/maast_rows")


def export(lats):
    import jax.numpy as jnp

    from oaraim import geometry
    from oaraim.errors import AIRBORNE_MODELS, gnss_variances
    from oaraim.geometry.sky import look_angles
    from oaraim.readers import GPS
    from oaraim.studies import availability_map as am

    p = am.AvailabilityMap().validate({})
    ecef, ok, cons, sv, t_off, _ = am.constellation_orbits(p["gps"], p["galileo"],
                                                           p["duration_s"], p["step_s"],
                                                           p["sky_time"])
    DIR.mkdir(exist_ok=True)
    rows = []
    user = AIRBORNE_MODELS[p["airborne_model"]]
    prn = np.where(cons == GPS, 1, 101) + np.array(
        [int("".join(c for c in str(s) if c.isdigit()) or 0) % 100 for s in sv])
    for lat in lats:
        for lon in np.asarray(p["lon_deg"]):
            rx = geometry.geodetic_to_ecef(np.deg2rad(lat), np.deg2rad(lon), p["height_m"])
            az, el, _, vis = (np.asarray(x) for x in look_angles(
                rx, jnp.asarray(ecef), jnp.asarray(ok), np.deg2rad(p["mask_deg"])))
            for t in range(len(t_off)):
                k = np.flatnonzero(vis[t])
                g = np.asarray(geometry.geometry_rows(az[t, k], el[t, k]))
                is_gps = cons[k] == GPS
                vi_g, va_g = gnss_variances(el[t, k], p["sigma_ura_gps_m"], user_model=user)
                vi_e, va_e = gnss_variances(el[t, k], p["sigma_ura_gal_m"], user_model=user)
                vi = np.where(is_gps, vi_g, vi_e)
                va = np.where(is_gps, va_g, va_e)
                b = np.where(is_gps, p["b_nom_gps_m"], p["b_nom_gal_m"])
                ps = np.where(is_gps, p["p_sat_gps"], p["p_sat_gal"])
                u = len(rows) and rows[-1][0] + 1 or 1
                for i in range(k.size):
                    rows.append((u, *g[i], vi[i], va[i], b[i], ps[i], prn[k[i]], lat, lon, t))
                if k.size == 0:
                    rows.append((u, 0, 0, 0, np.inf, np.inf, 0, 0, 1, lat, lon, t))
    np.savetxt(DIR / "los.txt", np.asarray(rows, float), fmt="%.12g")
    (DIR / "params.json").write_text(json.dumps(
        {"p_const_gps": p["p_const_gps"], "p_const_gal": p["p_const_gal"],
         "lats": list(lats)}))
    print(f"{len(rows)} lines of {rows[-1][0]} user-epochs to {DIR / 'los.txt'}")


def compare(out_dir):
    import xarray as xr

    m = np.loadtxt(DIR / "maast_vhpl.txt")  # per user-epoch: lat lon t vpl emt sig_acc hpl
    ds = xr.open_zarr(Path(out_dir) / "availability-map" / "data.zarr", consolidated=False)
    lats, lons = ds["lat_deg"].values, ds["lon_deg"].values
    li = np.searchsorted(lats, m[:, 0])
    lj = np.searchsorted(lons, m[:, 1])
    t = m[:, 2].astype(int)
    ours = {k: ds[k].values[li, lj, t] for k in ("vpl_m", "hpl_m", "emt_m", "sigma_acc_m",
                                                  "available", "position_adjusted")}
    maast = {"vpl_m": m[:, 3], "emt_m": m[:, 4], "sigma_acc_m": m[:, 5], "hpl_m": m[:, 6]}
    report = {}
    for k in ("vpl_m", "hpl_m", "emt_m", "sigma_acc_m"):
        both = np.isfinite(ours[k]) & np.isfinite(maast[k])
        rel = (maast[k][both] - ours[k][both]) / ours[k][both]
        report[k] = {"compared": int(both.sum()),
                     "finite_only_ours": int((np.isfinite(ours[k]) & ~both).sum()),
                     "finite_only_maast": int((np.isfinite(maast[k]) & ~both).sum()),
                     "median_rel_diff_pct": 100 * float(np.median(rel)),
                     "median_abs_rel_diff_pct": 100 * float(np.median(np.abs(rel))),
                     "p95_abs_rel_diff_pct": 100 * float(np.percentile(np.abs(rel), 95))}
    req = ds.attrs
    ok_maast = ((maast["vpl_m"] <= req["val_m_limit"]) & (maast["hpl_m"] <= req["hal_m_limit"])
                & (maast["emt_m"] <= req["emt_m_limit"])
                & (maast["sigma_acc_m"] <= req["sigma_acc_v_m_limit"]))
    key = np.stack([li, lj], 1)
    pts = np.unique(key, axis=0)
    a_o = np.array([ours["available"][(key == q).all(1)].mean() for q in pts])
    a_m = np.array([ok_maast[(key == q).all(1)].mean() for q in pts])
    report["epochs_available"] = {"ours": int(ours["available"].sum()),
                                  "maast": int(ok_maast.sum()), "of": int(t.size),
                                  "disagree": int((ours["available"] != ok_maast).sum())}
    report["points_at_target"] = {"ours": int((a_o >= 0.995).sum()),
                                  "maast": int((a_m >= 0.995).sum()), "of": int(pts.shape[0])}
    report["epochs_position_adjusted_ours"] = int(ours["position_adjusted"].sum())
    print(json.dumps(report, indent=1))


def fixture(opt_txt, noopt_txt, every):
    """tests/data/maast_map_rows.json: every ``every``-th user-epoch of los.txt with MAAST's
    outputs under its defaults (``maast_map_rows.m``, OPT.txt) and with prm.opt = 0 and every
    target 0 (the PL bisection run to its tolerance, NOOPT.txt; the same .m with those four
    lines changed), keyed by (lat, lon, epoch)."""
    d = np.loadtxt(DIR / "los.txt")
    outs = [{tuple(r[:3]): r[3:] for r in np.loadtxt(f)} for f in (opt_txt, noopt_txt)]
    cases = []
    for u in np.unique(d[:, 0])[::every]:
        rows = d[d[:, 0] == u]
        key = tuple(rows[0, 9:12])
        if key not in outs[0] or key not in outs[1]:
            continue
        a, b = outs[0][key], outs[1][key]
        cases.append({
            "lat_deg": key[0], "lon_deg": key[1], "epoch": int(key[2]),
            "g": rows[:, 1:4].round(12).tolist(), "var_int_m2": rows[:, 4].tolist(),
            "var_acc_m2": rows[:, 5].tolist(), "b_nom_m": rows[:, 6].tolist(),
            "p_sat": rows[:, 7].tolist(), "galileo": (rows[:, 8] > 100).astype(int).tolist(),
            "maast": {"vpl_m": a[0], "emt_m": a[1], "sigma_acc_m": a[2], "hpl_m": a[3]},
            "maast_no_opt_no_target": {"vpl_m": b[0], "emt_m": b[1], "sigma_acc_m": b[2],
                                       "hpl_m": b[3]}})
    pj = json.loads((DIR / "params.json").read_text())
    out = Path(__file__).parent.parent / "tests" / "data" / "maast_map_rows.json"
    out.write_text(json.dumps({"p_const": [pj["p_const_gps"], pj["p_const_gal"]],
                               "cases": cases}, indent=None))
    print(f"{len(cases)} cases to {out}")


if __name__ == "__main__":
    if sys.argv[1] == "export":
        export([float(x) for x in sys.argv[2:]])
    elif sys.argv[1] == "fixture":
        fixture(sys.argv[2], sys.argv[3], int(sys.argv[4]))
    else:
        compare(sys.argv[2])
