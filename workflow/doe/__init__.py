"""The design-of-experiments stage (paper section 2.1, Tables 3-4): the central
composite design of finger depth, length and breadth and the OpenSim scale
factors per run (:mod:`.ccd`); rule entry points in :mod:`.entry`.
"""

from __future__ import annotations
