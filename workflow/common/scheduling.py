"""Queue order of the workflow's jobs: read by the rules only.

No job script imports this module, so the order can change without rerunning any job whose code inputs
(:func:`workflow.common.provenance.code_files`) would otherwise take it in.
"""

from __future__ import annotations

from workflow.common.fidelity_choice import FemCase

__all__ = ["fem_case_priority"]


def fem_case_priority(case: FemCase) -> int:
    """Snakemake priority of an FE study case's job: the longer it runs, the earlier it starts (3D before 2D, finer
    before coarser, contact before none), all above 10 so that the study, which every sweep waits for, runs before
    any other rule (priority 0).  In a cold run the 3D 1 mm case takes about 16 min, the 1.4 mm one 6, every 2D case
    under 3: started fourth, the 1 mm case left one core idle for 7 min."""
    return 10 + (100 if case.model == "3d" else 0) + int(round((10.0 if case.contact else 1.0) / case.h_mm))
