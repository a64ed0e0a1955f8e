"""A path that stops says whether its tangent was nearly singular (a limit point) or regular (a non-smooth stall)."""

from __future__ import annotations

import numpy as np
import pytest

from workflow import fem
from workflow.fem import _linsolve
from workflow.fem._solve import _stall_diagnosis, tangent_eigenvalue
from workflow.fem._unit import unit_model


def test_tangent_eigenvalue_is_the_dense_eigenvalue_nearest_zero():
    um = fem.build_unit_mesh(h=2.0, dim=2)
    model = unit_model(um, 150.0, 0.0, "free", contact=False)
    u = np.zeros(model.nstate)
    ours = tangent_eigenvalue(model, u, 0.0, um.mesh.p)
    _, K, _ = model.evaluate(u, 0.0, um.mesh.p)
    dense = np.linalg.eigvals(_linsolve.reduce_matrix(K, model.T).toarray())
    nearest = dense[np.argmin(np.abs(dense))]
    assert ours == pytest.approx(nearest.real, rel=1e-6)
    assert ours > 0  # the unloaded unit is stable


@pytest.mark.parametrize(
    "last, start, says",
    [(-1e-6, 2e-5, "past a limit or bifurcation point"), (1e-6, 2e-5, "a limit point"), (5e-5, 2e-5, "non-smooth")],
)
def test_the_stall_diagnosis_reads_the_eigenvalue_against_the_start(last, start, says):
    assert says in _stall_diagnosis(last, start)
    assert _stall_diagnosis(np.nan, start) == ""


def test_a_path_that_stops_records_the_diagnosis():
    um = fem.build_unit_mesh(h=2.0, dim=2)
    # one Newton iteration per step never converges: every step is cut back until the step is below its minimum
    res = fem.solve_unit(um, 150.0, 0.0, "free", contact=False, solver={"max_iter": 1, "min_step": 0.01})
    assert res.status == 1 and res.load_factor == 0.0
    # both attempts of the last step are named (the retry alone would hide the first's failure), then the diagnosis
    first, retry, diagnosis = res.reason.split("; ", 2)
    assert (first, retry) == ("no convergence (with line search)", "no convergence (without line search)")
    assert diagnosis.startswith("the tangent stays regular") and "not a limit point" in diagnosis
    # too many unknowns to examine: the reason is the solver's alone
    res = fem.solve_unit(
        um, 150.0, 0.0, "free", contact=False, solver={"max_iter": 1, "min_step": 0.01, "diagnose_max_unknowns": 10}
    )
    assert res.reason == "no convergence (with line search); no convergence (without line search)"
