"""All studies by name."""

from oaraim.studies.availability_map import AvailabilityMap
from oaraim.studies.integrity_risk import IntegrityRisk
from oaraim.studies.rinex_replay import RinexReplay
from oaraim.studies.seed000_ekf_raim import Seed000EkfRaim
from oaraim.studies.seed001_fig3 import Fig3Elevation
from oaraim.studies.seed001_fig4 import Fig4HplCdf
from oaraim.studies.seed001_fig5 import Fig5Madrid24h
from oaraim.studies.seed001_vehicle import Seed001Vehicle
from oaraim.studies.seed002_outlier import Seed002Outlier
from oaraim.studies.seed004_fig3 import Fig3OneSop
from oaraim.studies.seed004_fig4 import Fig4HplMaps
from oaraim.studies.seed004_theorems import Theorems
from oaraim.studies.seed004_uav import Seed004Uav

STUDIES = {s.name: s for s in (Fig3Elevation(), Fig4HplCdf(), Fig5Madrid24h(), Fig3OneSop(),
                                Fig4HplMaps(), Theorems(), RinexReplay(), Seed000EkfRaim(),
                                Seed002Outlier(), Seed001Vehicle(), Seed004Uav(),
                                AvailabilityMap(), IntegrityRisk())}


def get_study(name):
    """The registered study called ``name``; ValueError naming the known studies if none is."""
    try:
        return STUDIES[name]
    except KeyError:
        raise ValueError(f"unknown study {name!r}; known studies: {', '.join(STUDIES)}") from None
