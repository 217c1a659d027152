"""Integrity must be able to fail on real data: a step and a ramp injected on one satellite
of the TLSE hour (``rinex-replay --set fault=...``). With the monitor (``fde=on``, the default)
the MHSS detects and excludes the satellite and no epoch is misleading; with it disabled
(``fde=off``: the all-in-view position and PLs whatever the tests say) the same faults give
misleading epochs, HPE > HPL or VPE > VPL."""

import numpy as np
import pytest

from oaraim.registry import STUDIES
from oaraim.studies import rinex_replay

TLSE = ("obs3/TLSE00FRA_R_20240011800_01H_30S_MO.crx.gz",
        "obs3/BRDC00IGS_R_20240010000_01D_MN.rnx.gz")


def _run(shared_data, **sets):
    study = STUDIES["rinex-replay"]
    params = study.validate({"obs": str(shared_data / TLSE[0]),
                             "nav": str(shared_data / TLSE[1])} | sets)
    return study.run(params, 120, 0, None)


def test_fault_text_and_bias_by_hand():
    """A step of 30 m from 600 s and a ramp of 0.5 m/s from 900 s on 30 s epochs: zero before
    the onset, 30 m from it; the ramp 0, 15, 30 m at 900, 930, 960 s."""
    text = rinex_replay.parse_faults("fault", " g05,step,30,600; E11,ramp,0.5,900 ")
    assert text == "G05,step,30,600;E11,ramp,0.5,900"
    t = 1e9 + np.arange(0.0, 1200.0, 30.0)
    b = rinex_replay.fault_bias_m(text, t, np.array(["E11", "G05", "G07"]))
    np.testing.assert_array_equal(b[:, 1], np.where(t - t[0] >= 600, 30.0, 0.0))
    assert b[30:33, 0].tolist() == [0.0, 15.0, 30.0] and not b[:30, 0].any()
    assert not b[:, 2].any()
    for bad in ("G05,jump,3,0", "G05,step,3", "G05,step,x,0", "G05,step,3,-1"):
        with pytest.raises(ValueError, match="fault must be 'none' or SV,step,BIAS_M,ONSET_S"):
            rinex_replay.parse_faults("fault", bad)
    with pytest.raises(ValueError, match="fault: G99 is not among the satellites used"):
        rinex_replay.fault_bias_m("G99,step,1,0", t, np.array(["G05"]))


@pytest.mark.parametrize("fault", ["G25,step,100,600", "G25,ramp,0.2,600"],
                         ids=["step", "ramp"])
def test_monitor_detects_and_excludes_and_without_it_counts_mi(shared_data, fault):
    """G25 (a GPS IIF satellite used at every epoch of the hour): from 600 s (epoch 20) a 100 m
    step, or a ramp of 0.2 m/s (12 m a minute, 60 m at the hour's end). Monitored: detected
    and G25 excluded at most fault epochs (the ramp's first minutes stay under the
    threshold), 0 misleading epochs, exclusions only of G25. Unmonitored: the same errors
    exceed the all-in-view PLs. Measured: step 71 detections, 69 misleading epochs
    unmonitored; ramp 69 and 62."""
    clean = _run(shared_data).metrics
    on = _run(shared_data, fault=fault).metrics
    off = _run(shared_data, fault=fault, fde="off").metrics
    assert clean["detections_mhss"] == 0 and clean["misleading_information_epochs"] == 0
    assert on["misleading_information_epochs"] == 0
    assert on["detections_mhss"] >= 50 and on["exclusions_mhss"] == on["detections_mhss"]
    assert on["excluded_share"]["G25"] >= 0.5
    assert all(v == 0 for k, v in on["excluded_share"].items() if k != "G25")
    assert on["hpe_mhss_max_m"] < 3.0 and on["hpe_max_m"] > 5.0  # kept vs all-in-view
    assert off["misleading_information_epochs"] >= 30
    assert off["exclusions_mhss"] == 0 and off["detections_mhss"] == on["detections_mhss"]


def test_fault_on_a_satellite_never_used_warns(shared_data):
    """G10 is observed but never above the mask in the hour: nothing is injected, said so."""
    with pytest.warns(UserWarning, match="fault on G10: the satellite is never used"):
        m = _run(shared_data, fault="G10,step,60,0").metrics
    assert m["detections_mhss"] == 0
