"""The fidelity stage: speed against accuracy of every fidelity the workflow
offers, and the cheapest one that meets a stated tolerance per stage.

Pure analysis (:mod:`.analysis`: errors, Richardson extrapolation, Pareto
fronts), the study's tables (:mod:`.tables`).  Rule entry points: :mod:`.entry` and :mod:`.entry_fem` (the FE
cases, apart so that judging the study does not rerun its FEA); figures in
:mod:`.plots`.  The stages read the choices through
:mod:`workflow.common.fidelity_choice`.
"""

from __future__ import annotations
