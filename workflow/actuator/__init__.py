"""The actuator stage (paper section 3.1): what one PNA unit does under pressure.

Pressure sweeps of the FE unit models (:mod:`.sweep`), surrogates with k-fold
cross-validation (:mod:`.surrogates`), the 2D-to-3D pressure mapping
(:mod:`.mapping`), the reduced-order unit model the cascade plans with
(:mod:`.unit_model`), the converged region of a sweep (:mod:`.sampled_region`),
the unit under an external end moment (:mod:`.moment_check`) and the silicone's
pressure limit (:mod:`.pressure_limit`).  Rule entry points: :mod:`.entry`
(cheap file-level steps) and :mod:`.entry_fem` (the FE sweeps and the unit
check, apart so that editing the fitting code does not rerun their FEA).
"""

from __future__ import annotations
