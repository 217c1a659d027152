"""What several studies share; a study imports ``studies.base`` and ``studies.common``, never
another study.

- ``sky``: the ``nav`` parameter and where a run's GPS ephemeris comes from (seed 001 Fig. 5,
  the seed 004 studies, the availability map).
- ``seed004``: seed 004's receiver, Table I, the GPS sky table, the MHSS inputs and the cell
  kernel of Figs. 3 and 4 (also the integrity-risk, theorem, UAV and vehicle studies).
- ``ekf_drive``: the EKF-RAIM drive study of seeds 000 and 002.
- ``params``: the ``Param`` declarations several studies repeat.
- ``plotting``: figure helpers (plots read stored results only).

The submodules are imported by name (``from oaraim.studies.common import seed004``), so a
study loads only what it uses.
"""
