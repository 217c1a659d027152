"""Bit-identity check for kernel speed-ups: a speed-up keeps the same results bit for bit.

    python tools/bit_identity.py save REF.npz     # on the code before the change
    python tools/bit_identity.py check REF.npz    # after it: every output compared exactly

Saves or compares the outputs of the availability map's kernel (rows at five latitudes, two
index ranges each, under add-v4.2 with and without BPP SOPs, add-v3 and blanch-2012, MAAST's
position estimator on) and of ``araim.protection_levels`` and ``select_fault_modes`` on the
bench's MHSS cases under every convention at orders 1 and 2: 828 arrays, ~5 min on 2 cores
(most of it compiling). ``check`` lists the arrays that differ with their largest difference;
exit status 1 if any does. Needs the real data (``OARAIM_DATA``)."""

import sys

import jax
import jax.numpy as jnp
import numpy as np

import oaraim  # noqa: F401  (float64, compilation cache)
from oaraim import araim
from oaraim.araim.fault_modes import fault_mode_rule, select_fault_modes, to_batch_last
from oaraim.bench import MHSS_CASES
from oaraim.registry import STUDIES
from oaraim.studies import availability_map as am

MAP_SETS = ({}, {"sops_per_km2": "0.5", "max_sops": "6"}, {"fault_modes": "add-v3"},
            {"fault_modes": "blanch-2012"})
LATITUDES_DEG = (-80.0, -35.0, 0.0, 40.0, 70.0)
RULES = ("add-v4.2", "add-v3", "add-v3-consolidated", "grouped")


def outputs():
    """{name: array} of every output compared."""
    out = {}
    study = STUDIES["availability-map"]
    for sets in MAP_SETS:
        p = study.validate({"lat_deg": "-90:90:1", "lon_deg": "-180:179:1", **sets})
        tag = ",".join(f"{k}={v}" for k, v in sets.items())
        for lat in LATITUDES_DEG:
            row = am.MapRow(p, lat)
            for start in (0, 50_000):
                r = row(np.arange(start, start + 2048), jax.random.key(3))
                for k, v in r.items():
                    out[f"map[{tag}]{lat}/{start}/{k}"] = np.asarray(v)
    for case, (inputs, budget_name, _, rule0) in MHSS_CASES.items():
        x = inputs(2048)
        budget = getattr(araim, budget_name)
        sources = araim.Sources(*(x[k] for k in ("g", "constellation", "var_int_m2",
                                                 "var_acc_m2", "b_nom_m", "p_sat", "valid")))
        for rule in sorted({rule0, *RULES}):
            for order in (1, 2):
                try:
                    r = araim.protection_levels(sources, x["p_const"], budget,
                                                araim.MHSSOptions(order, fault_modes=rule))
                except ValueError:  # an order the convention does not enumerate
                    continue
                for k, v in r._asdict().items():
                    out[f"pl[{case}/{rule}/{order}]{k}"] = np.asarray(v)
                a = [to_batch_last(jnp.asarray(x[k]), 1)
                     for k in ("valid", "constellation", "p_sat", "p_const")]
                fm = select_fault_modes(*a, budget, fault_mode_rule(rule), order)
                for k, v in fm._asdict().items():
                    out[f"fm[{case}/{rule}/{order}]{k}"] = np.asarray(v)
    return out


def main(argv):
    if len(argv) != 3 or argv[1] not in ("save", "check"):
        print(__doc__.split("\n\n")[1])
        return 2
    out = outputs()
    if argv[1] == "save":
        np.savez_compressed(argv[2], **out)
        print(f"saved {len(out)} arrays to {argv[2]}")
        return 0
    ref = np.load(argv[2])
    bad = [k for k in ref.files if k not in out or ref[k].shape != out[k].shape
           or not np.array_equal(ref[k], out[k], equal_nan=True)]
    print(f"compared {len(ref.files)}, differ {len(bad)}, "
          f"not in the reference {len(set(out) - set(ref.files))}")
    for k in bad:
        same_shape = k in out and ref[k].shape == out[k].shape
        if same_shape and ref[k].dtype.kind == "f":
            d = np.abs(ref[k] - out[k])
            d = d[np.isfinite(d)]
            print(f"  {k}: largest difference {d.max() if d.size else float('nan'):.3e}")
        else:
            print(f"  {k}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
