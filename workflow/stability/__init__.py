"""The stability stage: where each method fails or degrades.

Extra FE rays by mesh, contact and formulation (:mod:`.rays`), the failure,
locking and penetration tables from every FE sample (:mod:`.samples`), the
patients' coded levels and plans against the design region (:mod:`.design`).
Rule entry points in :mod:`.entry`, figures in :mod:`.plots`.
"""

from __future__ import annotations
