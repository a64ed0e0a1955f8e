"""The FEA check of the plans (paper section 3.2, Fig. 18-22).

The patient's 2D finger-actuator FE model (:mod:`.model`), the check of one
exercise at its plan's pressures (:mod:`.check`), the correction step: a
bounded quasi-Newton inverse on the FEA (:mod:`.correction`, :mod:`.inverse`), the check of a whole plan (:mod:`.run`) and the
stand-alone whole actuator in 2D and 3D (:mod:`.standalone`).  Rule entry
points in :mod:`.entry` and :mod:`.entry_standalone`, figures in :mod:`.plots`.
"""

from __future__ import annotations
