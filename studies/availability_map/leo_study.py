"""``availability-map-leo``: the availability map with Starlink shell 1 beside GPS + Galileo
(``availability-map --set leo=starlink``), a study of its own so that ``oaraim reproduce``
runs it and its full-size result has a report row.

Its defaults differ from ``availability-map`` in three keys: ``leo=starlink``, the 12 LEO
satellites of highest elevation above 25 deg, and P_s^LEO = 1e-6. The last is a stated
choice, not a source's: at P_s^LEO = 1e-5 (GPS's) the ADD's P_thresh rule asks for order 2
with 30-odd sources (pairs of satellites, ~400 modes), where the MHSS runs at ~40 PL/s and a
world day would take hours on 2 cores (docs/leo.md, "Cost"); at 1e-6 it stays at order 1.
GPS-only + LEO, the resilience question, is ``--set galileo=none``.
"""

import dataclasses

from oaraim.studies.availability_map import AvailabilityMap


class AvailabilityMapLeo(AvailabilityMap):
    """``availability-map`` with ``leo=starlink`` and P_s^LEO = 1e-6 by default."""

    name = "availability-map-leo"
    title = ("ARAIM availability and coverage map with a LEO constellation (Starlink shell 1) "
             "beside GPS + Galileo, and the map without it")
    quick_cost_s = 90
    quick_sets = {"lat_deg": "40,50", "lon_deg": "0:20:10", "duration_s": "3600",
                  "coastlines": "none"}
    params = {**AvailabilityMap.params,
              "leo": dataclasses.replace(AvailabilityMap.params["leo"], default="starlink"),
              "p_s_leo": dataclasses.replace(AvailabilityMap.params["p_s_leo"], default=1e-6)}
