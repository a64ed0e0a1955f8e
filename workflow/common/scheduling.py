"""Queue order of the workflow's jobs: read by the rules only.

No job script imports this module, so the order can change without rerunning any job whose code inputs
(:func:`workflow.common.provenance.code_files`) would otherwise take it in.
"""

from __future__ import annotations

from workflow.common.fidelity_choice import FemCase

__all__ = ["CHECK_PRIORITY", "fem_case_priority", "fem_case_seconds", "sweep_shard_priority"]

#: The FEA check's mesh study and the FEA checks, the run's last jobs: ahead of the studies that become ready with
#: them and that nothing waits for (the unit stiffness study, the stand-alone exercises); below the FE study's cases.
CHECK_PRIORITY = 5


def fem_case_seconds(case: FemCase) -> float:
    """Estimated wall time of an FE study case, s: 411 s / h^3 in 3D, 9 s / h^2 in 2D (h in mm), a quarter / a fifth
    of that without contact; fitted to a cold run with the 3D steps at rtol = 1e-6 (3D 1 / 1.4 / 2 mm 411 / 187 / 67 s,
    2D 0.25 / 0.5 / 1 mm 149 / 40 / 9 s). Only the order matters: at the 3D default of 1e-2 on residual and increment
    the 3D cases took 296 / 143 / 43 s and the 2D ones 156 / 42 / 9 s, so two neighbours swap (2D 0.25 mm now
    outlasts 3D 1.4 mm by 13 s, 2D 0.5 mm 3D 2 mm by 1 s), which leaves the study at its floor on two cores (half its
    job-time: 5.9 min) as long as the 3D 1 mm case starts first."""
    if case.model == "3d":
        return 411.0 / case.h_mm**3 * (1.0 if case.contact else 0.25)
    return 9.0 / case.h_mm**2 * (1.0 if case.contact else 0.2)


def fem_case_priority(case: FemCase) -> int:
    """Snakemake priority of an FE study case's job: the longer it runs (:func:`fem_case_seconds`), the earlier it
    starts, all above 10 so that the study, which every sweep waits for, runs before any other rule (priority 0)."""
    return 11 + int(round(fem_case_seconds(case) / 5.0))


def sweep_shard_priority(fea: str, shard: int, n_shards: int) -> int:
    """Snakemake priority of a sweep shard's job: every plan waits for the sweeps, so they go ahead of the studies that
    nothing waits for (the end-moment check, the stability rays: priority 0), which then fill the cores while the
    check's mesh study runs alone; below the checks (:data:`CHECK_PRIORITY`), which become ready only after them.

    3D shards first, in the order of their rays' cost: ray k of the ratios P_B / P_T = 0 .. 1 is dealt to shard
    k mod ``n_shards``, and the more one-sided the pressure, the further the unit bends and the longer its ray runs
    (145 s at P_B = 0 down to 79 s at P_B = P_T solved), so the shards start in order (4 .. 2); the 2D shards
    (5-11 s each) at 1.  With ``fidelity.auto`` shard 0 reads its ray from the FE study (0.1 s), and shard 1 is the
    first that solves.
    """
    if fea == "3d":
        return 2 + (2 * (n_shards - 1 - shard)) // max(n_shards - 1, 1)
    return 1
