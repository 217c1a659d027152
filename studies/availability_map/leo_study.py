"""``availability-map-leo``: the availability map with Starlink shell 1 beside GPS + Galileo
(``availability-map --set leo=starlink``), a study of its own so that ``oaraim reproduce``
runs it and its full-size result has a report row.

Its defaults differ from ``availability-map`` in three keys: ``leo=starlink`` (the 12 LEO
satellites of highest elevation above 25 deg, the map's defaults), P_s^LEO = 1e-6 and
P_const^LEO = 1e-5. The last two are stated choices, not a source's: with GPS + Galileo (~22 in
view) and 12 LEO satellites, MAAST's LPV-200 budget (P_THRES 6e-8) asks the ADD for order 2
unless P_s^LEO <= 1e-6 and P_const^LEO <= 3e-5; at order 2 (pairs of satellites, ~400 modes)
the MHSS runs at ~40 PL/s and the world day took 19 min on 2 shared cores (docs/leo.md,
"Cost").
GPS-only + LEO, the resilience question, is ``--set galileo=none``.
"""

import dataclasses

from oaraim.studies.availability_map import AvailabilityMap


class AvailabilityMapLeo(AvailabilityMap):
    """``availability-map`` with ``leo=starlink``, P_s^LEO = 1e-6 and P_const^LEO = 1e-5 by
    default."""

    name = "availability-map-leo"
    title = ("ARAIM availability and coverage map with a LEO constellation (Starlink shell 1) "
             "beside GPS + Galileo, and the map without it")
    quick_cost_s = 90
    quick_sets = {"lat_deg": "40,50", "lon_deg": "0:20:10", "duration_s": "3600",
                  "coastlines": "none"}
    params = {**AvailabilityMap.params,
              "leo": dataclasses.replace(AvailabilityMap.params["leo"], default="starlink"),
              "p_s_leo": dataclasses.replace(AvailabilityMap.params["p_s_leo"], default=1e-6),
              "p_const_leo": dataclasses.replace(AvailabilityMap.params["p_const_leo"],
                                                 default=1e-5)}
