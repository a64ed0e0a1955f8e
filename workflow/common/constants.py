"""Names and code tables every stage shares, stated once.

The finger's joints and segments (sections 2.2-2.3), the actuator's four unit
groups and two chambers (section 3.1, Fig. 3), and every status-code table that
goes into a dataset as CF ``flag_values`` / ``flag_meanings``.  Each table is
named for what it flags; the stored integer codes are part of the data contract
(docs/contract.md) and must not change.
"""

from __future__ import annotations

__all__ = [
    "JOINTS",
    "SEGMENTS",
    "GROUPS",
    "CHAMBERS",
    "PRESSURE_NAMES",
    "SOLVER_STATUS",
    "SWEEP_SAMPLE_STATUS",
    "CASCADE_EQUILIBRIUM_STATUS",
    "OPENSIM_STATUS",
    "MAPPING_STATUS",
    "CHECK_MAPPING_STATUS",
    "UNIT_INVERSE_STATUS",
    "flag_attrs",
]

#: Finger joints, proximal to distal.
JOINTS = ("MCP", "PIP", "DIP")
#: Phalanges (proximal, middle, distal).
SEGMENTS = ("PP", "MP", "DP")
#: The actuator's unit groups, proximal to distal; each has its own pair of chamber pressures.
GROUPS = ("CMC", "MCP", "PIP", "DIP")
#: The two chambers of a bi-directional unit (top bends it into flexion, bottom into extension).
CHAMBERS = ("top", "bottom")
#: The eight pressures of a plan, in the order of Table 8 (P_T, P_B per group).
PRESSURE_NAMES = tuple(f"P_{g}_{c}" for g in GROUPS for c in ("T", "B"))

#: Newton path solve of the FE engine (workflow.fem).
SOLVER_STATUS = {0: "converged", 1: "step_size_below_minimum", 2: "too_many_steps", 3: "solver_error"}
#: One sample of a pressure sweep; a solver wrapper translates its own codes into these.
SWEEP_SAMPLE_STATUS = {
    0: "converged",
    1: "diverged",  # Newton failed after the allowed step cut-backs
    2: "not_reached",  # an earlier load step of the same ray failed
    3: "solver_error",  # the solver raised; the whole ray is recorded as failed
}
#: Forward solve of the reduced-order cascade (joint equilibrium under the unit moments).
CASCADE_EQUILIBRIUM_STATUS = {0: "converged", 1: "not_converged", 2: "non_finite"}
#: One pose of the OpenSim joint-moment sampling.
OPENSIM_STATUS = {0: "ok", 1: "equilibrium_failed", 2: "not_sampled"}
#: The 2D-to-3D pressure mapping of a planned pressure pair (Table 8 -> 2D).
MAPPING_STATUS = {0: "mapped", 1: "equal_pressures", 2: "outside_2d_grid"}
#: How the FEA check obtained each 2D pressure pair it applied.
CHECK_MAPPING_STATUS = {
    0: "mapped",
    1: "equal_pressures_kept",
    2: "capped_at_2d_grid_edge",
    3: "unchanged",
    4: "cut_back_to_the_pressure_limit",
}
#: The unit model's inverse (pressures for an angle under an end moment).
UNIT_INVERSE_STATUS = {0: "found", 1: "unreachable_within_p_max"}


def flag_attrs(table: dict[int, str], **extra: str) -> dict:
    """CF attributes of a status variable coded by ``table`` (flag_values in code order)."""
    import numpy as np

    codes = sorted(table)
    return {"flag_values": np.array(codes, dtype=np.int32), "flag_meanings": " ".join(table[c] for c in codes), **extra}
