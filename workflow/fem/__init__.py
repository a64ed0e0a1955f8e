"""Nonlinear FEA of the bi-directional PNA unit (scikit-fem; paper section 3.1).

Compact public API (like a FElupe job)::

    from workflow import fem
    mesh = fem.build_unit_mesh(geometry, h=0.5, dim=2)
    res = fem.solve_unit(mesh, p_top_kpa=300, p_bottom_kpa=0, case="free", contact=True)
    res.bending_angle_deg, res.status, res.history   # one dict per load step

Sweeps along a ray p = s (p_top, p_bottom), s in (0, 1]: one call per
ray and case; every accepted load step is a sample in ``res.history`` (keys
``p_top_kpa``, ``p_bottom_kpa``, ``bending_angle_deg``, ``bending_moment_nm``,
``max_penetration_mm``, ``iterations``, ``wall_time_s``); ``stops`` makes the
steps land on given s.  With the config section::

    res = fem.solve_unit_from_config(config["actuator"], 2, p_top, p_bottom, "free", stops=(0.25, 0.5))

A stalled ray returns ``status`` > 0 with the last converged ``load_factor``.

Case ``rotation`` holds the right end at a prescribed inclination and measures
the couple (the moment-angle curve between free and blocked)::

    res = fem.solve_unit(mesh, 180, 0, case="rotation", end_angle_deg=30.0, end_hold="backbone")

``end_hold`` (blocked and rotation): ``face`` (default) holds the whole end
face plane, ``backbone`` only its paper and base layers (see ``held_end_nodes``).

Physics: three-term Mooney-Rivlin silicone (Table 5) on isochoric invariants
with a mean-dilatation (Q1/P0, condensed) volumetric part K = bulk_ratio *
mu0; compressible neo-Hooke paper layer (E = 1.2 GPa, nu = 0.2) on
enhanced-strain (incompatible-mode) elements, which bend without shear
locking one element thick (``formulation``; ``FORMULATIONS``); follower
pressure on the cavity walls with its exact load stiffness; penalty
self-contact of every gap and every pocket (``ContactPair.self_contact``);
Newton with line search and adaptive load steps.  Every accepted step also
records the global overlap check (``overlap_measures``: deepest boundary
node inside a foreign element, smallest pocket).  Units: mm, MPa, N (kPa for
pressures and N m for the reported moments).

The whole-actuator models are public modules of their own:
:mod:`workflow.fem.actuator` (the stand-alone actuator of groups of units),
:mod:`workflow.fem.coupled` (the actuator strapped on a finger) and
:mod:`workflow.fem.finger2d` (the finger's 2D section).
"""

from ..common.constants import SOLVER_STATUS
from ._assembly import SolidAssembler
from ._config import layer_options, solve_unit_from_config, unit_check, unit_mesh_from_config
from ._contact import ContactPair
from ._material import mooney_rivlin_isochoric, neo_hooke_compressible
from ._mesh import DEFAULT_GEOMETRY, UnitMesh, build_grid_mesh, build_unit_mesh, layer_counts, top_bottom_symmetric
from ._overlap import overlap_depth, overlap_measures, pocket_sizes
from ._pressure import pressure_load
from ._restarts import cumulative_attempts, first_converged, separate_attempts
from ._solve import DEFAULT_SOLVER, Model, PathResult, linear_solve, solve_path
from ._unit import (
    CASES,
    DEFAULT_CONTACT,
    DEFAULT_END_HOLD,
    DEFAULT_FORMULATION,
    DEFAULT_MATERIAL,
    END_HOLDS,
    FORMULATIONS,
    UnitResult,
    clamp_inclination_deg,
    clamp_rotation,
    contact_band,
    contact_penalty,
    held_end_nodes,
    material_constants,
    solid_assembler,
    solve_unit,
    unit_model,
)

__all__ = [
    "CASES",
    "DEFAULT_CONTACT",
    "DEFAULT_END_HOLD",
    "DEFAULT_FORMULATION",
    "DEFAULT_GEOMETRY",
    "DEFAULT_MATERIAL",
    "DEFAULT_SOLVER",
    "END_HOLDS",
    "FORMULATIONS",
    "SOLVER_STATUS",
    "ContactPair",
    "Model",
    "PathResult",
    "SolidAssembler",
    "UnitMesh",
    "UnitResult",
    "build_grid_mesh",
    "build_unit_mesh",
    "clamp_inclination_deg",
    "clamp_rotation",
    "contact_band",
    "contact_penalty",
    "cumulative_attempts",
    "first_converged",
    "held_end_nodes",
    "layer_counts",
    "layer_options",
    "linear_solve",
    "material_constants",
    "mooney_rivlin_isochoric",
    "neo_hooke_compressible",
    "overlap_depth",
    "overlap_measures",
    "pocket_sizes",
    "pressure_load",
    "separate_attempts",
    "solid_assembler",
    "solve_path",
    "solve_unit",
    "solve_unit_from_config",
    "top_bottom_symmetric",
    "unit_check",
    "unit_mesh_from_config",
    "unit_model",
]
