"""The cascade stage (paper section 3.2, Fig. 15-18, Tables 7-8): pressure plans per patient.

The finger's mechanics (:mod:`.finger`), the reduced-order cascade of units on
it (:mod:`.model`), planning the pressures of each exercise
(:mod:`.planning`), a patient's finger and cascade from the config
(:mod:`.patient`), the comparison with Tables 8 and 10 (:mod:`.validation`).
Rule entry points in :mod:`.entry`, figures in :mod:`.plots`.
"""

from __future__ import annotations
