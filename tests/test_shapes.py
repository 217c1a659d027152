"""Shapes as types: the ``jaxtyping`` annotations of the functions the ``araim`` and
``geometry`` faces export, checked at run time by ``beartype`` in a subprocess (the rest of the
suite, and every production path, runs the plain functions).

The subprocess installs ``jaxtyping.install_import_hook(["oaraim.araim", "oaraim.geometry",
"oaraim.readers", "oaraim.errors.leo"], beartype)`` before it imports oaraim (the geometry face
re-exports the file readers' names, which live in ``oaraim.readers``; the araim face re-exports
``leo_variances`` of ``oaraim.errors.leo``), so every function of those packages checks its
arguments and its return against its annotations (named dimensions consistent across the
arguments of one call). It then calls every annotated exported function with small valid
inputs (they must pass: a valid call never fails the check), a jitted kernel under ``jax.jit``
(its tracers are checked at trace time), and a few calls with one argument of a wrong shape
(each must raise the checker's error naming that argument). The static test counts the
annotations with ``tools/structure.py`` (``shape_annotations``).

beartype runs with ``is_pep484_tower=True``: a ``float`` parameter takes an ``int`` (PEP 484's
numeric tower), as the functions themselves do.
"""

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: exported functions without an array in their signature (paths, names, probabilities,
#: dicts, orbit objects): fully annotated with plain types, no jaxtyping type to carry
NO_ARRAYS = {
    "araim": {"check_int", "check_positive", "check_probability", "check_range",
              "detection_threshold", "noncentrality", "fault_mode_rule", "replay_metrics"},
    "geometry": {"check_navigation_file", "load_navigation", "gps_24_slot", "galileo_walker",
                 "load_recording", "validate_recording", "write_recording", "read_clock_rinex",
                 "read_observation_table", "read_observations", "read_sem", "read_sp3",
                 "read_yuma", "resolve_source", "vn100", "combine_skies", "leo_constellation"},
}

#: the exported readers of real files: called in the data test
READERS = {"read_yuma", "read_sem", "check_navigation_file", "load_navigation", "read_sp3",
           "compare_broadcast_precise", "read_clock_rinex", "read_observations",
           "read_observation_table"}

HOOK = """
import jaxtyping
jaxtyping.install_import_hook(
    ["oaraim.araim", "oaraim.geometry", "oaraim.readers", "oaraim.errors.leo"],
    "beartype.beartype(conf=beartype.BeartypeConf(is_pep484_tower=True))")
"""

#: the calls with valid inputs, one entry per exported function; then the wrong shapes
SCRIPT = HOOK + r'''
import json, sys, tempfile, time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from oaraim import araim, errors, geometry, sim
from oaraim.araim import Sources
from oaraim.bench import mhss_bench_inputs

rng = np.random.default_rng(0)
B, L, C = 3, 13, 2
x = mhss_bench_inputs(B, seed=1)
src = Sources(*(jnp.asarray(x[k]) for k in Sources._fields))
p_const = jnp.asarray(x["p_const"])
TABLE_I = araim.BUDGET_SEED004_TABLE_I
GROUPED = araim.FaultModeRule("grouped")
ORDER = araim.MHSSOptions(1, fault_modes=GROUPED)
host = (src, p_const, TABLE_I)
y = jnp.zeros((B, L))
g, sig, valid = src.g, jnp.sqrt(src.var_int_m2), src.valid
table = jnp.asarray(araim.lambda_det_table(1e-3, 1e-3, L))

rx = np.asarray(geometry.geodetic_to_ecef(0.7, 0.1, 100.0))
tx = rx + rng.normal(size=(4, 8, 3)) * 2e7
pr = np.linalg.norm(tx - rx, axis=-1)
key = jax.random.key(0)
t_gps = 1.3e9 + np.arange(2) * 600.0
usable = rng.random((2, 5)) > 0.2

spec = errors.vn100()
params = araim.ekf.params_from_imu(spec, 0.01, 9.8)
state = araim.ekf_init([0, 0, 0, 1.0], np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3),
                       np.zeros(2), np.eye(17))
n, E, T = 5, 2, 3
imu = jnp.zeros((n, 3)).at[:, 2].set(9.8)
tw = jnp.asarray(rng.normal(size=(6, 3)) * 1e3)
z6 = jnp.linalg.norm(tw, axis=-1)
tables = araim.ekf_raim.raim_tables(1e-3, 1e-3, 6)

meta = {"format": "oaraim-recording", "format_version": 1,
        "origin": {"lat_deg": 0.0, "lon_deg": 0.0, "h_m": 0.0}}
towers = pd.DataFrame({"tx_id": ["A", "B", "C"], "kind": "lte", "group": "g",
                       "x_m": 6.4e6, "y_m": [0.0, 1.0, 2.0], "z_m": 0.0,
                       "clock_bias_m": 0.0, "clock_drift_mps": 0.0})
rows = pd.DataFrame([(0.0, "B", 10.0, 1.0), (0.0, "A", 11.0, 2.0), (1.0, "C", 12.0, 3.0)],
                    columns=["t_s", "tx_id", "pseudorange_m", "sigma_m"])
folder = Path(tempfile.mkdtemp())
rec = geometry.validate_recording(geometry.Recording(meta=meta, transmitters=towers,
                                                     pseudoranges=rows))
gnss_rec = sim.example_recording(duration_s=2.0, with_gnss=True)

replayed = {}

# a filter bank: 6 sources (3 + 3 in two clock groups), E = 2 epochs, linear state [ENU, 2 clocks]
con6 = np.array([0, 0, 0, 1, 1, 1])
bank_src = araim.BankSources(con6, np.full(6, 1e-5), np.array([1e-8, 1e-4]))
bank_opt = araim.BankOptions(TABLE_I, 1, "add-v4.2")
g6 = np.asarray(geometry.geometry_rows(rng.uniform(0, 6, 6), rng.uniform(0.2, 1.2, 6)))
h6 = jnp.asarray(np.concatenate([g6, np.eye(2)[con6]], -1))
lin = araim.LinearModel(jnp.stack([jnp.eye(5)] * E), jnp.zeros((E, 5, 5)),
                        jnp.stack([h6] * E), jnp.ones((E, 6)))
fm6, used6 = araim.filter_monitor.epoch_modes_and_used(
    jnp.ones(6, bool), jnp.asarray(con6), jnp.full(6, 1e-5), jnp.array([1e-8, 1e-4]), TABLE_I,
    araim.fault_mode_rule("add-v4.2"), 1)
K6 = used6.shape[0]
x_bank = jnp.zeros((K6, 3))
p_bank = jnp.eye(3) * (1.0 + jnp.arange(K6))[:, None, None]
starlink = geometry.leo_constellation("starlink", t_gps[0])


def replay():
    replayed["r"] = araim.replay(pr[:, :8], tx[:, :8],
                                 araim.ReplaySources(4.0, 4.0, np.ones((4, 8), bool)), rx,
                                 x0_m=rx + 100.0)
    return replayed["r"]


CALLS = {
    "araim": {
        "protection_levels": lambda: araim.protection_levels(*host, ORDER),
        "protection_levels_kernel": lambda: araim.protection_levels_kernel(
            src, p_const, TABLE_I, ORDER),
        "protection_levels_priors_kernel": lambda: araim.protection_levels_priors_kernel(
            src._replace(p_sat=jnp.stack([src.p_sat, 2 * src.p_sat])),
            jnp.stack([p_const, p_const]), TABLE_I, ORDER),
        "switch_flags_kernel": lambda: araim.switch_flags_kernel(src, p_const, TABLE_I, ORDER),
        "solution_separation": lambda: araim.solution_separation(*host, y, ORDER),
        "detect_and_exclude": lambda: araim.detect_and_exclude(*host, y, ORDER),
        "separation_kernel": lambda: araim.separation_kernel(src, p_const, TABLE_I, y, ORDER),
        "detect_and_exclude_kernel": lambda: araim.detect_and_exclude_kernel(
            src, p_const, TABLE_I, y, ORDER),
        "required_order": lambda: araim.required_order(src.valid, src.constellation, src.p_sat,
                                                       p_const, TABLE_I, fault_modes=GROUPED),
        "fault_modes_batch_last": lambda: araim.fault_modes_batch_last(
            src.valid.T, src.constellation.T, src.p_sat.T, p_const.T, 1e-8, 1),
        "fault_mode_rule": lambda: araim.fault_mode_rule("grouped"),
        "epoch_protection_levels": lambda: araim.epoch_protection_levels(
            40.0, 5.0, 100.0, 1.3e9,
            options=araim.EpochOptions(mhss=araim.MHSSOptions(1))),
        "exposure_probability": lambda: araim.exposure_probability(1e-5, 3600.0, 3600),
        "detection_threshold": lambda: araim.detection_threshold(1e-3, 3),
        "noncentrality": lambda: araim.noncentrality(1e-3, 1e-3, 3),
        "lambda_det_table": lambda: araim.lambda_det_table(1e-3, 1e-3, 4),
        "slopes": lambda: araim.slopes(np.asarray(g), 2.0),
        "slopes_kernel": lambda: araim.slopes_kernel(g, sig, valid),
        "slope_hpl": lambda: araim.slope_hpl(np.asarray(g), np.ones(L), 1e-3, 1e-3,
                                             np.asarray(valid)),
        "slope_hpl_kernel": lambda: araim.slope_hpl_kernel(g, sig, valid, table),
        "slope_hpl_tiled": lambda: araim.slope_hpl_tiled(g, sig, valid, table),
        "added_source_slope_max": lambda: araim.added_source_slope_max(
            g, sig, jnp.zeros(B), jnp.linspace(0.1, 1.0, 4), 3.0, valid),
        "wnls": lambda: araim.wnls(pr, tx, 1.0),
        "wnls_kernel": lambda: araim.wnls_kernel(
            jnp.asarray(pr), jnp.asarray(tx), jnp.ones((4, 8)), jnp.zeros((4, 4)),
            jnp.ones((4, 8), bool), jnp.zeros((4, 8), jnp.int32)),
        "check_int": lambda: araim.check_int("n", 3, 1),
        "check_positive": lambda: araim.check_positive("x", 2.0),
        "check_probability": lambda: araim.check_probability("p", 0.5),
        "check_range": lambda: araim.check_range("x", 1.0, 0.0, 2.0),
        "ekf_init": lambda: state,
        "ekf_predict": lambda: araim.ekf_predict(state, imu * 0, imu, params),
        "ekf_update": lambda: araim.ekf_update(state, z6, jnp.ones(6, bool), tw, jnp.zeros(6),
                                               1.0),
        "ekf_step": lambda: araim.ekf_step(state, araim.ekf.EkfInputs(
            imu * 0, imu, z6, jnp.ones(6, bool), jnp.zeros(6), jnp.ones(6)), tw, params),
        "run_ekf": lambda: araim.run_ekf(state, araim.ekf.EkfInputs(
            jnp.zeros((E, n, 3)), jnp.stack([imu] * E), jnp.stack([z6] * E),
            jnp.ones((E, 6), bool), jnp.zeros((E, 6)), 1.0), tw, params),
        "run_ekf_raim": lambda: araim.run_ekf_raim(
            state, araim.ekf.EkfInputs(jnp.zeros((E, n, 3)), jnp.stack([imu] * E),
                                       jnp.stack([z6] * E), jnp.ones((E, 6), bool),
                                       jnp.zeros((E, 6)), 1.0), tw, params,
            araim.ekf_raim.RaimOptions(tables)),
        "replay": replay,
        "replay_metrics": lambda: araim.replay_metrics(replayed["r"]),
        "leo_labels": lambda: araim.leo_labels(4, 2, "satellite"),
        "leo_variances": lambda: araim.leo_variances(
            np.full((2, 5), 0.5), araim.LEO_ISM["estimated"], araim.LEO_SIGNALS["starlink"]),
        "separation_monitor": lambda: araim.separation_monitor(x_bank, p_bank, fm6, TABLE_I),
        "run_linear_monitor": lambda: araim.run_linear_monitor(
            jnp.zeros(5), 1e12 * jnp.eye(5), lin, jnp.zeros((E, 6)), jnp.ones((E, 6), bool),
            bank_src, bank_opt),
        "run_ekf_monitor": lambda: araim.run_ekf_monitor(
            state, araim.ekf.EkfInputs(jnp.zeros((E, n, 3)), jnp.stack([imu] * E),
                                       jnp.stack([z6] * E), jnp.ones((E, 6), bool),
                                       jnp.zeros((E, 6)), 1.0), tw, params, bank_src, bank_opt),
        "epoch_risk_bound": lambda: araim.epoch_risk_bound(
            jnp.broadcast_to(jnp.eye(2), (E, 2, 2)), jnp.zeros((E, 2)), jnp.full(E, 5.0),
            jnp.zeros((E, 3, 3)), jnp.ones((E, 3, 3)), jnp.full((E, 3, 3), 5.0)),
    },
    "geometry": {
        "geodetic_to_ecef": lambda: geometry.geodetic_to_ecef(np.zeros(4), 0.1, 10),
        "ecef_to_geodetic": lambda: geometry.ecef_to_geodetic(tx),
        "enu_rotation": lambda: geometry.enu_rotation(0.1, np.zeros((2, 3))),
        "ecef_to_enu": lambda: geometry.ecef_to_enu(tx, rx),
        "enu_to_ecef": lambda: geometry.enu_to_ecef(tx, rx),
        "azimuth_elevation": lambda: geometry.azimuth_elevation(rx[None, None], tx),
        "az_el_from_rotation": lambda: geometry.az_el_from_rotation(
            geometry.enu_rotation(0.7, 0.1), tx - rx),
        "earth_rotation_correction": lambda: geometry.earth_rotation_correction(tx, 0.07),
        "normal_gravity_mps2": lambda: geometry.normal_gravity_mps2(0.7, np.zeros(3)),
        "geometry_rows": lambda: geometry.geometry_rows(np.ones((2, 5)), 0.5),
        "geometry_rows_enu": lambda: geometry.geometry_rows_enu(tx, np.zeros(3)),
        "random_sky": lambda: geometry.random_sky(key, 7, 0.1, (2,)),
        "bpp_towers": lambda: geometry.bpp_towers(key, 4, 5.0, 3000.0, batch_shape=(2,)),
        "gps_24_slot": geometry.gps_24_slot,
        "galileo_walker": geometry.galileo_walker,
        "resolve_source": lambda: geometry.resolve_source("nominal"),
        "satellites": lambda: geometry.satellites("nominal", t_gps),
        "sky": lambda: geometry.sky(rx, t_gps),
        "ephemeris_gaps": lambda: geometry.ephemeris_gaps(usable, np.array([0, 0, 1, 1, 1])),
        "line_of_sight": lambda: geometry.line_of_sight(np.stack([rx, rx]), tx[:2]),
        "azimuth": lambda: geometry.azimuth(np.ones(3), 2.0),
        "elevation": lambda: geometry.elevation(np.ones(3), 2.0, np.ones((2, 3))),
        "look_angles": lambda: geometry.look_angles(rx, tx[:2], usable[:, :1].repeat(8, 1),
                                                    0.1),
        "first_near_pair": lambda: geometry.first_near_pair(tx[0], ["A"] * 8),
        "vn100": lambda: spec,
        "validate_recording": lambda: rec,
        "pseudorange_matrix": lambda: geometry.pseudorange_matrix(rec),
        "tower_clock_m": lambda: geometry.tower_clock_m(rec, np.arange(3.0)),
        "write_recording": lambda: geometry.write_recording(folder / "drive", rec),
        "load_recording": lambda: geometry.load_recording(folder / "drive"),
        "gnss_matrix": lambda: geometry.gnss_matrix(gnss_rec, value=["sat_x_m", "sat_y_m",
                                                                      "sat_z_m"]),
        "walker_tle_text": lambda: geometry.walker_tle_text(
            geometry.LEO_PRESETS["starlink"], t_gps[0], 400),
        "leo_constellation": lambda: starlink,
        "leo_sky": lambda: geometry.leo_sky(rx, t_gps, starlink),
        "combine_skies": lambda: geometry.combine_skies(geometry.sky(rx, t_gps),
                                                       geometry.leo_sky(rx, t_gps, "iridium")),
    },
}

DATA = Path(sys.argv[1]) if len(sys.argv) > 1 else None
if DATA is not None:
    from tests.test_almanac import _sem_text

    yuma = geometry.read_yuma(DATA / "almanac" / "almyuma_01jan2020.txt")
    (folder / "x.al3").write_text(_sem_text(yuma))
    (folder / "x.clk").write_text("\n".join([
        "     3.00           C                   M                   RINEX VERSION / TYPE",
        "   GPS                                                      TIME SYSTEM ID",
        "                                                            END OF HEADER",
        "AS G01  2023  1  1  0  0  0.000000  1    0.230218024731E-03"]))
    nav = DATA / "nav" / "brdc1820.10n"
    orbits = {}
    CALLS = {"geometry": {  # the readers alone: the rest ran in the test without files
        "read_yuma": lambda: yuma,
        "read_sem": lambda: geometry.read_sem(folder / "x.al3"),
        "check_navigation_file": lambda: geometry.check_navigation_file(nav),
        "load_navigation": lambda: orbits.setdefault("eph", geometry.load_navigation(nav)),
        "read_sp3": lambda: orbits.setdefault(
            "sp3", geometry.read_sp3(DATA / "orbits" / "igs15904.sp3")),
        "compare_broadcast_precise": lambda: geometry.compare_broadcast_precise(
            orbits["eph"], orbits["sp3"], t_gps_s=orbits["sp3"].t_gps_s[:2]),
        "read_clock_rinex": lambda: geometry.read_clock_rinex(folder / "x.clk", "G"),
        "read_observations": lambda: geometry.read_observations(
            DATA / "obs" / "07590920.05o", max_epochs=3),
        "read_observation_table": lambda: geometry.read_observation_table(
            DATA / "obs" / "07590920.05o"),
    }}

out = {"called": {}, "errors": {}, "seconds": {}}
for face, calls in CALLS.items():
    for name, call in calls.items():
        try:
            t0 = time.perf_counter()
            jax.block_until_ready(call())
            out["seconds"][name] = round(time.perf_counter() - t0, 2)
            out["called"].setdefault(face, []).append(name)
        except Exception as e:  # report every failing call, not just the first
            out["errors"][f"{face}.{name}"] = f"{type(e).__name__}: {str(e)[:600]}"

# a jitted kernel: the tracers are checked once, at trace time
jitted = jax.jit(araim.slopes_kernel)
jitted(g, sig, valid)
try:
    jitted(g, sig[:, :-1], valid)
    out["errors"]["jit wrong shape"] = "no error"
except jaxtyping.TypeCheckError as e:
    out["jit_wrong_shape"] = "sigma_m" in str(e)

# one argument of a wrong shape: the checker's error names it
WRONG = {
    "sigma_m": lambda: araim.slopes(np.asarray(g), np.ones(L + 1)),
    "tx_pos_m": lambda: araim.wnls(pr, tx[..., :2], 1.0),
    "p_const": lambda: araim.protection_levels(src, np.float64(1e-8), TABLE_I, ORDER),
    "tx_pos": lambda: araim.ekf_update(state, z6, jnp.ones(6, bool), tw[:, :2], jnp.zeros(6),
                                       1.0),
    "tx_enu_m": lambda: geometry.geometry_rows_enu(np.ones((2, 5, 4))),
    "sat_ecef_m": lambda: geometry.look_angles(rx, tx[0], usable, 0.1),
    "x_pos": lambda: araim.separation_monitor(x_bank[:, :2], p_bank, fm6, TABLE_I),
    "receiver_ecef_m": lambda: geometry.leo_sky(rx[:2], t_gps, starlink),
}
out["wrong"] = {}
for arg, call in WRONG.items():
    try:
        call()
        out["wrong"][arg] = "no error"
    except jaxtyping.TypeCheckError as e:
        out["wrong"][arg] = "named" if f"parameter '{arg}'" in str(e) else str(e)[:400]
print("RESULT " + json.dumps(out))
'''


def _run(*args):
    env = dict(os.environ, PYTHONPATH=str(ROOT), JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", SCRIPT, *map(str, args)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=600)
    lines = [x for x in proc.stdout.splitlines() if x.startswith("RESULT ")]
    assert proc.returncode == 0 and lines, proc.stderr[-4000:]
    return json.loads(lines[-1][len("RESULT "):])


def _exported_functions(face):
    structure = _structure()
    return set(structure.shape_annotations(ROOT)[face]["names"])


def _structure():
    spec = importlib.util.spec_from_file_location("structure", ROOT / "tools" / "structure.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _check(out, faces_done):
    assert out["errors"] == {}
    for face, done in faces_done.items():
        missing = _exported_functions(face) - set(out["called"][face]) - done
        assert not missing, f"exported {face} functions not called under the checker: {missing}"


def test_annotated_functions_pass_valid_calls_and_name_a_wrong_shape():
    """Every annotated exported function of araim and geometry but the readers of real files
    (next test) takes a valid call under the checker; a jitted kernel too; a wrong shape is
    the checker's error naming the argument."""
    out = _run()
    _check(out, {"araim": set(), "geometry": READERS})
    assert out["jit_wrong_shape"] is True
    assert out["wrong"] == dict.fromkeys(
        ["sigma_m", "tx_pos_m", "p_const", "tx_pos", "tx_enu_m", "sat_ecef_m", "x_pos",
         "receiver_ecef_m"], "named")


@pytest.mark.data
def test_readers_of_real_files_pass_the_checker(shared_data):
    """The readers on the project's real files (almanacs, a navigation file, SP3, RINEX 2
    observations) and a one-line clock file, under the checker."""
    out = _run(shared_data)
    assert out["errors"] == {}
    assert set(out["called"]) == {"geometry"} and set(out["called"]["geometry"]) == READERS


def test_exported_functions_carry_shapes_as_types():
    """Every exported function of araim and geometry is fully annotated, and each one with an
    array in its signature carries a jaxtyping type; the count is what tools/structure.py
    reports (docs/design.md quotes it)."""
    counts = _structure().shape_annotations(ROOT)
    for face in ("araim", "geometry"):
        c = counts[face]
        unshaped = {name.rsplit(".", 1)[1] for name in c["unshaped"]}
        assert unshaped == NO_ARRAYS[face], face
        assert c["unannotated"] == [] and c["annotated"] == c["functions"], face
        assert c["shaped"] == c["functions"] - len(unshaped)
        # the counts quoted in docs/design.md
        print(face, c["shaped"], c["annotated"], c["functions"])


def test_the_count_follows_faces_wrappers_aliases_and_lazy_names(tmp_path):
    """``shape_annotations`` on a made-up tree: a name exported through the face, a jitted
    function (``name = jax.jit(body)``: the body's annotations count), a module-level alias of
    a jaxtyping type, a name the face loads on first use (PEP 562) beside a same-named
    function of another module, and a namespace module (not a function)."""
    (tmp_path / "pyproject.toml").write_text(
        '[tool.setuptools.package-dir]\n"oaraim" = "oaraim"\n"oaraim.araim" = "araim"\n'
        '"oaraim.geometry" = "geometry"\n')
    files = {
        "oaraim/__init__.py": "",
        "araim/__init__.py": (
            "from oaraim.araim import k\n"
            "from oaraim.araim.k import aliased, jitted, plain, shaped\n"
            '__all__ = ["aliased", "jitted", "k", "plain", "shaped"]\n'),
        "araim/k.py": (
            "import jax\nfrom jaxtyping import Array, Float\n"
            '_A = Float[Array, " n"]\n'
            'def shaped(x: Float[Array, "n 3"]) -> Float[Array, " n"]: ...\n'
            "def plain(name: str, x) -> int: ...\n"
            "def _body(x: _A) -> _A: ...\n"
            "jitted = jax.jit(_body)\n"
            "def aliased(x: _A, y: int) -> _A: ...\n"),
        "geometry/__init__.py": (
            '__all__ = ["lazy"]\n'
            "def __getattr__(name):\n"
            "    import importlib\n"
            '    for module_name in ("rec",):\n'
            '        return getattr(importlib.import_module(f"oaraim.geometry.{module_name}"),'
            " name)\n"),
        "geometry/rec.py": 'def lazy(t: "Real[ArrayLike, \' T\']") -> None: ...\n',
        "geometry/other.py": "def lazy(x): ...\n",
    }
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    got = _structure().shape_annotations(tmp_path)
    assert got["araim"] == {"functions": 4, "annotated": 3, "shaped": 3,
                            "names": ["aliased", "jitted", "plain", "shaped"],
                            "unshaped": ["oaraim.araim.k.plain"],
                            "unannotated": ["oaraim.araim.k.plain"]}
    assert got["geometry"] == {"functions": 1, "annotated": 1, "shaped": 1, "names": ["lazy"],
                               "unshaped": [], "unannotated": []}
