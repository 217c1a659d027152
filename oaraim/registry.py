"""All studies by name.

The registry names each study's module and class and imports a study when it is first asked
for, so ``oaraim run STUDY`` (and a Dask worker that rebuilds a study's kernel) loads that
study's module only; ``oaraim list`` and ``oaraim report`` go through every study and load them
all. The app layer imports the studies; no study imports the registry.
"""

import importlib
from collections.abc import MutableMapping

#: name -> "module of oaraim.studies:class", in the order ``oaraim list`` and the report use
STUDY_CLASSES = {
    "seed001-fig3-elevation": "seed001_fig3:Fig3Elevation",
    "seed001-fig4-hpl-cdf": "seed001_fig4:Fig4HplCdf",
    "seed001-fig5-madrid-24h": "seed001_fig5:Fig5Madrid24h",
    "seed004-fig3-one-sop": "seed004_fig3:Fig3OneSop",
    "seed004-fig4-hpl-maps": "seed004_fig4:Fig4HplMaps",
    "seed004-theorems": "seed004_theorems:Theorems",
    "rinex-replay": "rinex_replay:RinexReplay",
    "rinex-compare": "rinex_compare:RinexCompare",
    "seed000-ekf-raim": "seed000_ekf_raim:Seed000EkfRaim",
    "seed002-outlier": "seed002_outlier:Seed002Outlier",
    "seed001-vehicle": "seed001_vehicle:Seed001Vehicle",
    "seed004-uav": "seed004_uav:Seed004Uav",
    "availability-map": "availability_map:AvailabilityMap",
    "integrity-risk": "integrity_risk:IntegrityRisk",
    "tower-placement": "tower_placement:TowerPlacement",
    "sop-requirements": "sop_requirements:SopRequirements",
    "leo-sensitivity": "leo_sensitivity:LeoSensitivity",
    "availability-map-leo": "availability_map.leo_study:AvailabilityMapLeo",
    "filter-integrity": "filter_integrity:FilterIntegrity",
}


class StudyRegistry(MutableMapping):
    """A mapping name -> study object whose studies are built on first access.

    Each entry is a study object or the text ``"module:Class"`` of a module of
    ``oaraim.studies``; looking a name up imports that module alone and keeps the object, so
    every lookup of a name gives the same object. Keys, ``in`` and ``len`` import nothing;
    ``values()`` and ``items()`` build every study. Assigning a name registers a study object
    (tests register their own this way).
    """

    def __init__(self, entries):
        self._entries = dict(entries)

    def __getitem__(self, name):
        entry = self._entries[name]
        if isinstance(entry, str):
            module, _, cls = entry.partition(":")
            entry = getattr(importlib.import_module(f"oaraim.studies.{module}"), cls)()
            if entry.name != name:
                raise RuntimeError(f"the registry lists {cls} as {name!r} but its name is "
                                   f"{entry.name!r}; correct STUDY_CLASSES in oaraim/registry.py")
            self._entries[name] = entry
        return entry

    def is_builtin(self, name):
        """Whether ``name`` is the study ``STUDY_CLASSES`` names (a new process, which imports
        the registry afresh, builds the same one), not one registered at run time."""
        entry = self._entries.get(name)
        spec = STUDY_CLASSES.get(name)
        if entry is None or spec is None:
            return False
        if isinstance(entry, str):
            return entry == spec
        module, _, cls = spec.partition(":")
        return type(entry) is getattr(importlib.import_module(f"oaraim.studies.{module}"), cls)

    def __setitem__(self, name, study):
        self._entries[name] = study

    def __delitem__(self, name):
        del self._entries[name]

    def __contains__(self, name):
        return name in self._entries

    def __iter__(self):
        return iter(self._entries)

    def __len__(self):
        return len(self._entries)

    def __repr__(self):
        return f"StudyRegistry({', '.join(self._entries)})"


STUDIES = StudyRegistry(STUDY_CLASSES)


def get_study(name):
    """The registered study called ``name``; ValueError naming the known studies if none is."""
    try:
        return STUDIES[name]
    except KeyError:
        raise ValueError(f"unknown study {name!r}; known studies: {', '.join(STUDIES)}") from None
