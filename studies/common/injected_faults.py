"""Faults injected into a replay's pseudoranges (``--set fault=``) and the unmonitored user
(``--set fde=off``): integrity must be able to fail, and a test shows it does."""

import numpy as np

from oaraim import araim

FAULT_KINDS = ("step", "ramp")


def parse_faults(name, v):
    """'none' or 'SV,KIND,SIZE,ONSET_S[;...]' (``FAULT_KINDS``: step SIZE in m, ramp in m/s)
    -> the canonical text ('none' or the faults joined by ';')."""
    s = str(v).strip()
    if s in ("", "none"):
        return "none"
    out = []
    for part in s.split(";"):
        f = [x.strip() for x in part.split(",")]
        try:
            sv, kind, size, onset = f[0].upper(), f[1], float(f[2]), float(f[3])
            ok = (len(f) == 4 and len(sv) == 3 and sv[0].isalpha() and sv[1:].isdigit()
                  and kind in FAULT_KINDS and np.isfinite(size) and np.isfinite(onset)
                  and onset >= 0)
        except (IndexError, ValueError):
            ok = False
        if not ok:
            raise ValueError(f"{name} must be 'none' or SV,step,BIAS_M,ONSET_S or "
                             "SV,ramp,RATE_M_PER_S,ONSET_S (e.g. G05,ramp,0.5,600; onset "
                             f"seconds after the first epoch, >= 0), got {part.strip()!r}")
        out.append(f"{sv},{kind},{size:g},{onset:g}")
    return ";".join(out)


def fault_bias_m(fault, t_gps_s, sv):
    """(T, S) pseudorange errors of the ``fault`` text (``parse_faults``) at the epochs
    ``t_gps_s`` on the satellites ``sv`` (zeros for 'none'); an SV not in ``sv``: one-line
    error."""
    t = np.asarray(t_gps_s, np.float64)
    bias = np.zeros((t.size, len(sv)))
    if fault == "none":
        return bias
    names = [str(x) for x in sv]
    for part in fault.split(";"):
        s_v, kind, size, onset = part.split(",")
        if s_v not in names:
            raise ValueError(f"fault: {s_v} is not among the satellites used "
                             f"({', '.join(names[:6])}...); pick one the file observes")
        dt = t - (t[0] if t.size else 0.0) - float(onset)
        on = dt >= 0
        grow = float(size) * (dt if kind == "ramp" else 1.0)
        bias[:, names.index(s_v)] += np.where(on, grow, 0.0)
    return bias


def unmonitored(out):
    """``fde=off``: the MHSS and slope results of the user without the monitors' decisions:
    all-in-view position errors and PLs at every epoch, nothing excluded. The LPV-200 share
    keeps the EMT and sigma_acc of the solution the MHSS kept (the all-in-view one wherever it
    detected nothing)."""
    o = dict(out)
    for kind in ("mhss", "slope"):
        o[f"hpe_{kind}_m"], o[f"vpe_{kind}_m"] = out["hpe_m"], out["vpe_m"]
        o[f"hpl_{kind}_m"] = out[f"hpl_{kind}_aiv_m"]
        o[f"vpl_{kind}_m"] = out[f"vpl_{kind}_aiv_m"]
        o[f"{kind}_excluded"] = np.zeros_like(out[f"{kind}_excluded"])
        failed = out[f"{kind}_status"] == araim.Status.EXCLUSION_FAILED
        o[f"{kind}_status"] = np.where(failed & np.isfinite(o[f"hpl_{kind}_m"]),
                                       araim.Status.OK, out[f"{kind}_status"]).astype(np.int8)
    return o
