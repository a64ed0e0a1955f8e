"""Nonlinear static solver: Newton-Raphson with adaptive load stepping.

A ``Model`` holds the body (``SolidAssembler``), follower pressures, penalty
contact pairs and the kinematic constraints u = T v + lam u_D (fixed dofs are
left out of T; a "tie" group of dofs shares one column, e.g. the axial
displacement of an end face that must stay plane).  ``solve_path`` ramps the
load factor lam from 0 to 1 (pressures and prescribed displacements scale with
lam) with adaptive steps: a step that diverges, produces an inverted element
(J <= 0), a non-finite or singular solve, or needs more than ``max_iter``
iterations is cut back and retried; a step that converges fast lets the next
one grow.  A failed path is a result (``status`` > 0, last converged load),
never an exception.

Over 400 lines: the Newton path solve, its step control, line search and history are one loop.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np
import scipy.sparse as sp

from . import _linsolve
from ._assembly import Pattern, SolidAssembler, vector_dofs
from ._pressure import pressure_load

__all__ = ["Model", "PathResult", "solve_path", "DEFAULT_SOLVER", "linear_solve"]

log = logging.getLogger(__name__)

#: A path that runs longer than this logs its progress this often (s): the 3D rays of the FE study run for minutes.
PROGRESS_EVERY_S = 60.0


#: Step control and tolerances (config ``actuator.solver``).
DEFAULT_SOLVER = {
    "initial_step": 0.025,  # first load-factor increment (0.1 is cut back on the unit rays: ~10 % more iterations)
    "min_step": 1.0e-4,  # give up below this increment
    "max_step": 0.25,  # largest increment
    "max_steps": 400,  # accepted + rejected steps
    "max_iterations": None,  # Newton iterations of the whole path (None: no limit); a budget, not a wall time,
    # so that where a solve stops does not depend on the machine
    "max_iter": 15,  # Newton iterations per step
    "grow_below_iter": None,  # grow the step when a step took fewer iterations; None by dimension (BY_DIMENSION)
    "grow": 1.5,
    "cut": 0.5,
    # a step has converged when |r| <= max(rtol (|f_ext| + |reactions|), atol) and, where utol is set (not None or
    # inf), the last Newton correction |du| <= utol |u - u_step_start| (MSC Marc's residual-and-displacement test, which
    # the paper ran at 0.03 on both); None by dimension (BY_DIMENSION)
    "rtol": None,
    "atol": 1.0e-10,  # N
    "utol": None,
    # first guess of a step: True extrapolates the last increment, None by dimension (measured on the unit's rays,
    # docs/fea.md): in 2D it saves 30 % of the free ray's iterations; in 3D the contact steps cut back more with it
    # (2 mm free ray: 748 against 557 iterations; without contact and with the lagged volumetric pressure it pays)
    "predictor": None,
    "line_search": True,  # Matthies-Strang line search on the Newton correction
    # a path that stops compares the tangent's eigenvalue nearest zero at its last converged state with the one at
    # its start when it has at most this many unknowns: a limit point or a non-smooth stall (docs/fea.md)
    "diagnose_max_unknowns": 60000,
}


#: What a None in ``DEFAULT_SOLVER`` (or the config) stands for, per model dimension, all measured on the unit's
#: rays (docs/fea.md): in 3D a step grows after fewer than 8 iterations (a third fewer iterations per ray), converges
#: at 1e-2 on the residual and on the increment (a quarter to a half fewer, values within 0.03 %) and takes no
#: predictor (its contact steps cut back more with one); in 2D rtol = 1e-4 already stalls the free ray, and the
#: predictor saves 30 % of its iterations.  A None that stays None (utol in 2D) switches the test off.
BY_DIMENSION = {
    2: {"grow_below_iter": 6, "rtol": 1.0e-6, "utol": None, "predictor": True},
    3: {"grow_below_iter": 8, "rtol": 1.0e-2, "utol": 1.0e-2, "predictor": False},
}


def by_dimension(opts: Mapping, dim: int) -> dict:
    """``opts`` with each None that :data:`BY_DIMENSION` has a value for replaced by the ``dim``-D one."""
    out = dict(opts)
    for key, value in BY_DIMENSION[dim].items():
        if out.get(key) is None:
            out[key] = value
    return out


def linear_solve(A: sp.csr_matrix, b: np.ndarray) -> np.ndarray:
    """Sparse direct solve: PARDISO (analysis kept while the pattern stays) when importable, else SuperLU."""
    return _linsolve.default_solver.solve(A, b)


class Model:
    """Residual and tangent of body + follower pressures + contact under constraints.

    Parameters
    ----------
    solid : SolidAssembler
    pressures : dict name -> (facets, p) with p in MPa at lam = 1
    contacts : list of ContactPair
    penalty : float
        Contact penalty stiffness eps, MPa/mm.
    fixed : array of dofs held at zero
    prescribed : dict dof -> value (mm) at lam = 1
    ties : list of arrays of dofs that share one unknown
    offsets : dict dof -> value (mm) at lam = 1 for tied dofs: u = shared + lam * offset
        (e.g. an end face held plane at a prescribed inclination).  Each tie
        group needs one member without an offset: it carries the shared value.
    extras : list of objects with ``evaluate(x, u, lam, tangent) -> (f (n,), K (n, n) sparse or None)``
        Further internal-force terms added to the residual (springs, hinges,
        straps, dead loads as negative forces); ``x`` are the current node
        positions (dim, nnodes).  An extra may also have ``external(x, u, lam)
        -> f (n,)``: the part of its force that is an applied load (a dead
        load), counted in the convergence reference like the pressures.
        Without it, the extra's force enters the reference by its norm (a
        spring's force is a reaction-like internal force of the same scale).
    updaters : list of objects with ``increment(p_ref, u, du) -> du'``
        Map a Newton correction (or a predictor) to the increment actually
        applied: equal to du to first order, e.g. the finite rotation of a
        nearly rigid body instead of its linearisation (see
        ``_finger2d.RigidRotationUpdate``).  Applied in order; the converged
        solution does not depend on them, only the path of the iterations.
    """

    def __init__(
        self,
        solid: SolidAssembler,
        pressures=None,
        contacts=(),
        penalty=0.0,
        fixed=(),
        prescribed=None,
        ties=(),
        offsets=None,
        extras=(),
        updaters=(),
    ):
        self.solid = solid
        self.p0 = solid.mesh_p if hasattr(solid, "mesh_p") else None
        self.pressures = dict(pressures or {})
        self.contacts = list(contacts)
        self.penalty = float(penalty)
        n = solid.ndofs
        self.n = n  # nodal dofs; the state adds solid.n_internal enhanced parameters
        self.nstate = getattr(solid, "nstate", n)
        prescribed = dict(prescribed or {})
        self.uD = np.zeros(n)
        for dof, val in prescribed.items():
            self.uD[dof] = val
        offsets = dict(offsets or {})
        for dof, val in offsets.items():
            self.uD[dof] = val
        self.extras = list(extras)
        self.updaters = list(updaters)
        blocked = np.zeros(n, bool)
        blocked[np.asarray(list(fixed), dtype=int)] = True
        blocked[np.asarray(list(prescribed), dtype=int)] = True
        self.constrained = np.flatnonzero(blocked)
        col = -np.ones(n, dtype=np.int64)
        tied = np.zeros(n, bool)
        for grp in ties:
            tied[np.asarray(grp)] = True
        free = np.flatnonzero(~blocked & ~tied)
        col[free] = np.arange(free.size)
        m = free.size
        rep = list(free)  # per unknown, a dof that carries it without offset
        for grp in ties:
            grp = np.asarray(grp)
            grp = grp[~blocked[grp]]
            carriers = grp[self.uD[grp] == 0.0]
            if grp.size and not carriers.size:
                raise ValueError("every tie group needs one dof without an offset")
            col[grp] = m
            rep.append(carriers[0])
            m += 1
        rows = np.flatnonzero(col >= 0)
        self.T = sp.csr_matrix((np.ones(rows.size), (rows, col[rows])), shape=(n, m))
        self.m = m
        self.rep = np.asarray(rep, dtype=np.int64)
        # fixed sparsity: body + pressure facets
        r_list, c_list = [solid.rows], [solid.cols]
        for facets, _ in self.pressures.values():
            fd = vector_dofs(facets, solid.dim)
            k = fd.shape[1]
            r_list.append(np.repeat(fd, k, axis=1).ravel())
            c_list.append(np.tile(fd, (1, k)).ravel())
        self.pattern = Pattern(np.concatenate(r_list), np.concatenate(c_list), n)
        self.timing = {"assembly_s": 0.0, "solve_s": 0.0}

    def increment(self, u: np.ndarray, du: np.ndarray, p_ref: np.ndarray) -> np.ndarray:
        """State u advanced by the correction du (nodal part through the ``updaters``; u + du without them)."""
        n = self.n
        dn = du[:n]
        for upd in self.updaters:
            dn = upd.increment(p_ref, u[:n], dn)
        return u + (np.concatenate([dn, du[n:]]) if self.updaters else du)

    def positions(self, u: np.ndarray, p_ref: np.ndarray) -> np.ndarray:
        """Current nodal coordinates (dim, nnodes) of the state (or nodal displacements) u."""
        return p_ref + u[: self.n].reshape(-1, self.solid.dim).T

    def evaluate(self, u: np.ndarray, lam: float, p_ref: np.ndarray, tangent: bool = True):
        """Nodal residual r = f_int + f_contact - f_ext, tangent (csr, enhanced parameters condensed) and info.

        ``info["r_internal"]`` is the residual of the enhanced parameters and,
        with a tangent, ``info["r_condensed"]`` the nodal residual of the
        condensed system (see ``SolidAssembler``).
        """
        t0 = time.perf_counter()
        d = self.solid.dim
        f_full, kvals, jmin = self.solid.assemble(u, tangent)
        f_int = f_full[: self.n]
        u = u[: self.n]
        info = {"jmin": jmin, "gmin": np.inf, "r_internal": f_full[self.n :]}
        if not jmin > 0:
            self.timing["assembly_s"] += time.perf_counter() - t0
            return None, None, info
        x = self.positions(u, p_ref)
        f_ext = np.zeros(self.n)
        vals = [kvals] if tangent else []
        for facets, p in self.pressures.values():
            fe, Ke = pressure_load(x, facets, lam * p, tangent)
            fd = vector_dofs(facets, d)
            f_ext += np.bincount(fd.ravel(), weights=fe.reshape(fe.shape[0], -1).ravel(), minlength=self.n)
            if tangent:
                vals.append(Ke.ravel())
        r = f_int - f_ext
        K = self.pattern.matrix(np.concatenate(vals)) if tangent else None
        f_ref2 = 0.0  # squared norm of the extras' loads for the convergence reference
        for extra in self.extras:
            fx, Kx = extra.evaluate(x, u, lam, tangent)
            r = r + fx
            fe = extra.external(x, u, lam) if hasattr(extra, "external") else fx
            f_ref2 += float(fe @ fe)
            if tangent and Kx is not None:
                K = K + sp.csr_matrix(Kx)
        if self.contacts and self.penalty > 0:
            cr, cc, cv = [], [], []
            for pair in self.contacts:
                dofs, fc, Kc, gmin = pair.evaluate(x, self.penalty, tangent)
                info["gmin"] = min(info["gmin"], gmin)
                if dofs.size:
                    r += np.bincount(dofs.ravel(), weights=fc.ravel(), minlength=self.n)
                    if tangent:
                        k = dofs.shape[1]
                        cr.append(np.repeat(dofs, k, axis=1).ravel())
                        cc.append(np.tile(dofs, (1, k)).ravel())
                        cv.append(Kc.ravel())
            if tangent and cr:
                K = K + sp.csr_matrix(
                    (np.concatenate(cv), (np.concatenate(cr), np.concatenate(cc))), shape=(self.n, self.n)
                )
        info["f_ext_norm"] = float(np.sqrt(f_ext @ f_ext + f_ref2))
        info["r"] = r
        if tangent and self.nstate > self.n:
            info["r_condensed"] = r + self.solid.condensed_correction()
        self.timing["assembly_s"] += time.perf_counter() - t0
        return r, K, info


@dataclass
class PathResult:
    """Outcome of ``solve_path``: final state, status and per-step history.

    ``u`` is the nodal displacement (mm, node-interleaved); ``state`` the full
    solver state (``u`` followed by the enhanced parameters), the start of a
    follow-on path (``solve_path(..., u0=result.state)``).
    """

    u: np.ndarray
    lam: float
    status: int
    reason: str
    iterations: int
    steps: int
    cutbacks: int
    history: list = field(default_factory=list)
    timing: dict = field(default_factory=dict)
    state: np.ndarray | None = field(default=None, repr=False)
    #: a path that stopped: the real part of the reduced tangent's eigenvalue nearest zero at the last converged
    #: state, N/mm (NaN if not examined)
    min_eigenvalue: float = np.nan


def tangent_eigenvalue(model: Model, u: np.ndarray, lam: float, p_ref: np.ndarray) -> float:
    """Real part of the eigenvalue nearest zero of the reduced tangent T^T K T at the state u, N/mm.

    The tangent is not symmetric (follower pressure, interpolated contact normals), so this is the eigenvalue of
    the matrix itself (shift-invert Arnoldi just below zero), not of its symmetric part.  Along a stable loading path
    every eigenvalue has a positive real part; one that has crossed zero marks a limit or bifurcation point, where no
    load step under load control can converge.  NaN if it cannot be computed.
    """
    import scipy.sparse.linalg as sla

    _, K, _ = model.evaluate(u, lam, p_ref)
    if K is None:
        return np.nan
    Kr = _linsolve.reduce_matrix(K, model.T).tocsc()
    shift = -1e-9 * float(np.median(np.abs(Kr.diagonal()))) or -1e-12
    try:
        # bounded: a stop's diagnosis must never cost more than the stop
        vals = sla.eigs(
            Kr, k=min(3, Kr.shape[0] - 2), sigma=shift, which="LM", return_eigenvectors=False, tol=1e-8, maxiter=300
        )
    except Exception:  # a singular shift or no convergence of the Arnoldi iteration: say nothing
        return np.nan
    return float(vals[np.argmin(np.abs(vals))].real)


def _stall_diagnosis(last: float, start: float) -> str:
    """What the eigenvalue nearest zero at the last converged state (``last``) and at the path's start says, N/mm."""
    if not (np.isfinite(last) and np.isfinite(start)):
        return ""
    where = f"eigenvalue nearest zero {last:.2g} N/mm there, {start:.2g} at the start"
    if last < 0:
        return f"; the tangent has a negative eigenvalue ({where}): past a limit or bifurcation point"
    if last < 0.1 * start:
        return f"; the tangent is nearly singular ({where}): a limit point"
    return f"; the tangent stays regular ({where}): a non-smooth stall (contact or an element inverting), not a limit point"


def _slope(model: Model, u: np.ndarray, du: np.ndarray, lam: float, p_ref: np.ndarray):
    """du . r(u + du): the residual of the whole state (nodal and enhanced) along the correction, and that
    residual's (r, info) (None if an element inverted)."""
    r, _, info = model.evaluate(model.increment(u, du, p_ref), lam, p_ref, tangent=False)
    if r is None:
        return np.inf, None
    return float(du[: model.n] @ r + du[model.n :] @ info["r_internal"]), (r, info)


def _line_search(
    model: Model,
    u: np.ndarray,
    du: np.ndarray,
    s0: float,
    lam: float,
    p_ref: np.ndarray,
    ratio: float = 0.5,
    trials: int = 3,
):
    """Scale the Newton correction so that the residual's component along it drops.

    s(a) = du . r(u + a du); s0 = s(0) < 0 for a descent direction.  The full
    step is kept when |s(1)| <= ratio |s(0)| (Newton near the solution);
    otherwise a few regula-falsi steps on s (the Matthies-Strang / Crisfield
    line search).  This tames the first iterations of a load step, where the
    linearised rotation of nearly incompressible and of stiff paper elements
    causes large spurious volumetric stresses.

    Returns the scaled correction and, where the full step is kept, the residual (r, info) there: Newton's
    convergence test at the new state needs nothing more, so the step's last iteration forms no tangent.
    """
    if not s0 < 0:
        return du, None
    a_lo, s_lo, a_hi = 0.0, s0, 1.0
    s_hi, full = _slope(model, u, du, lam, p_ref)
    if np.isfinite(s_hi) and abs(s_hi) <= ratio * abs(s0):
        return du, full
    a = 1.0
    for _ in range(trials):
        if not np.isfinite(s_hi):
            a = 0.5 * (a_lo + a_hi)
        else:
            if s_hi < 0:  # still descending at the full step: take it
                return du * a_hi, (full if a_hi == 1.0 else None)
            a = a_lo - s_lo * (a_hi - a_lo) / (s_hi - s_lo)
            a = min(max(a, a_lo + 0.1 * (a_hi - a_lo)), a_lo + 0.9 * (a_hi - a_lo))
        sa = _slope(model, u, a * du, lam, p_ref)[0] / a
        if np.isfinite(sa) and abs(sa) <= ratio * abs(s0):
            return a * du, None
        if np.isfinite(sa) and sa < 0:
            a_lo, s_lo = a, sa
        else:
            a_hi, s_hi = a, sa
    return a * du, None


def _residual_norm(model: Model, r: np.ndarray, info: dict, opts: dict) -> tuple[float, float]:
    """|r| over the free nodal and the enhanced unknowns, and the tolerance max(rtol (|f_ext| + |reactions|), atol)."""
    rr = model.T.T @ r
    ri = info["r_internal"]
    ref = info["f_ext_norm"] + float(np.linalg.norm(r[model.constrained]))
    return float(np.sqrt(rr @ rr + ri @ ri)), max(opts["rtol"] * ref, opts["atol"])


def _newton(model: Model, u0: np.ndarray, lam: float, p_ref: np.ndarray, opts: dict):
    """Newton iterations at fixed lam on the state u0; returns (ok, u, iterations, reason, info)."""
    T = model.T
    n = model.n
    # u = T v + lam uD: the unknowns v are read from their carrier dofs, so
    # prescribed values and tie offsets follow the new load factor
    u = np.concatenate([model.T @ u0[model.rep] + lam * model.uD, u0[n:]])
    u_begin = u[:n].copy()
    r0 = None
    info = {}
    known = None  # the residual (r, info) of u when the line search already formed it
    last_du = np.inf  # |du| of the last correction applied, mm

    def small_correction():
        """The increment test (``utol``; None or inf: none): the last correction against the step's displacement."""
        if opts["utol"] is None or np.isinf(opts["utol"]):
            return True
        # + 1e-14 mm: a step whose state does not move (no load change) passes once its corrections vanish
        return last_du <= opts["utol"] * float(np.linalg.norm(u[:n] - u_begin)) + 1e-14

    for it in range(1, opts["max_iter"] + 1):
        if known is not None:  # test convergence on it first: at the step's last iterate no tangent is needed
            norm, tol = _residual_norm(model, *known, opts)
            if norm <= tol and small_correction():
                return True, u, it - 1, "", known[1]
        r, K, info = model.evaluate(u, lam, p_ref)
        if r is None:
            return False, u, it, "inverted element", info
        ri = info["r_internal"]
        norm, tol = _residual_norm(model, r, info, opts)
        if not np.isfinite(norm):
            return False, u, it, "non-finite residual", info
        if it > 1 and norm <= tol and small_correction():
            return True, u, it - 1, "", info
        if r0 is None:
            r0 = max(norm, 1e-300)
        elif norm > 1e6 * r0:
            return False, u, it, "diverged", info
        Kr = _linsolve.reduce_matrix(K, T)
        t0 = time.perf_counter()
        try:
            dv = linear_solve(Kr, -(T.T @ info.get("r_condensed", r)))
        except Exception as exc:  # singular or solver failure: cut back
            return False, u, it, f"linear solve failed: {exc}", info
        finally:
            model.timing["solve_s"] += time.perf_counter() - t0
        if not np.all(np.isfinite(dv)):
            return False, u, it, "singular tangent", info
        du = T @ dv
        if model.nstate > n:
            du = np.concatenate([du, model.solid.recover(du)])
        known = None
        if opts["line_search"]:
            du, known = _line_search(model, u, du, float(du[:n] @ r + du[n:] @ ri), lam, p_ref)
        last_du = float(np.linalg.norm(du[:n]))
        u = model.increment(u, du, p_ref)
    return False, u, opts["max_iter"], "no convergence", info


def solve_path(
    model: Model,
    p_ref: np.ndarray,
    options: dict | None = None,
    measure: Callable | None = None,
    u0: np.ndarray | None = None,
    stops=(),
) -> PathResult:
    """Ramp the load factor from 0 to 1 with adaptive steps.

    ``measure(u, lam, info)`` is called after every accepted step (u: the
    state; ``model.positions(u, p_ref)`` gives the nodes); its dict is stored
    in ``history`` together with lam, the Newton iterations, the smallest
    contact gap and the elapsed wall time.  The steps land exactly on every
    load factor in ``stops`` (0 < stop <= 1).  ``u0``: nodal displacements or
    a full state (``PathResult.state``) to start from.
    """
    opts = by_dimension({**DEFAULT_SOLVER, **dict(options or {})}, model.solid.dim)
    predict = bool(opts["predictor"])
    # each path starts from its own analysis: PARDISO's ordering follows the analysed pattern, so a pattern carried
    # over from an earlier model of the same size would make this path's round-off depend on what ran before
    _linsolve.default_solver.reset()
    t_start = time.perf_counter()
    if u0 is None:
        u = np.zeros(model.nstate)
    elif np.size(u0) == model.nstate:
        u = np.array(u0, float)
    elif hasattr(model.solid, "state"):
        u = model.solid.state(np.asarray(u0, float))
    else:
        u = np.concatenate([np.asarray(u0, float), np.zeros(model.nstate - model.n)])
    u_prev, u_start = u.copy(), u.copy()
    frictional = [pair for pair in model.contacts if pair.mu > 0.0]
    lam, dlam, dlam_prev = 0.0, float(opts["initial_step"]), 0.0
    history, iters, steps, cuts = [], 0, 0, 0
    status, reason = 0, ""
    t_said = t_start
    while lam < 1.0 - 1e-12:
        if steps >= opts["max_steps"]:
            status, reason = 2, "too many steps"
            break
        if opts["max_iterations"] is not None and iters >= opts["max_iterations"]:
            status, reason = 2, f"Newton iteration budget ({int(opts['max_iterations'])}) spent"
            break
        dlam = min(dlam, 1.0 - lam)
        nxt = min([st for st in stops if st > lam + 1e-12], default=1.0)
        step = min(dlam, nxt - lam)
        target = lam + step if nxt - (lam + step) > 1e-9 else nxt
        guess = u
        if predict and dlam_prev > 0:
            guess = u + ((target - lam) / dlam_prev) * (u - u_prev)
        steps += 1
        # a step that fails is retried once with the line search switched (it
        # helps in some contact states and hurts in others) before cutting back
        whys = []
        for ls in (opts["line_search"], not opts["line_search"]):
            try:
                ok, u_new, its, why, info = _newton(model, guess, target, p_ref, dict(opts, line_search=ls))
            except Exception as exc:  # never let one point stop a sweep
                ok, u_new, its, why, info = False, u, 0, f"error: {exc!r}", {}
            iters += its
            whys.append(f"{why} ({'with' if ls else 'without'} line search)")
            if ok or why.startswith("inverted"):
                break
        # a stop names every attempt's failure: the retry's (often an inverted element) alone hides the first's
        why = "; ".join(whys)
        if ok:
            u_prev, u = u, u_new
            lam, dlam_prev = target, target - lam
            if frictional:  # path-dependent contact state (friction anchors) moves on with the path
                x_acc = model.positions(u, p_ref)
                for pair in frictional:
                    pair.commit(x_acc, model.penalty)
            rec = {
                "lam": lam,
                "iterations": its,
                "gmin": info.get("gmin", np.inf),
                "wall_time_s": time.perf_counter() - t_start,
            }
            if measure is not None:
                rec.update(measure(u, lam, info))
            history.append(rec)
            if its < opts["grow_below_iter"]:
                dlam = min(dlam * opts["grow"], opts["max_step"])
            if time.perf_counter() - t_said >= PROGRESS_EVERY_S:
                t_said = time.perf_counter()
                log.info(
                    "load %.1f %% after %d steps (%d cut back), %d Newton iterations, %.0f s",
                    100 * lam,
                    steps,
                    cuts,
                    iters,
                    rec["wall_time_s"],
                )
        else:
            cuts += 1
            reason = why
            dlam = (target - lam) * opts["cut"]
            if dlam < opts["min_step"]:
                status = 1
                break
    if status == 0:
        reason = ""
    min_eig = np.nan
    if status == 1 and model.m <= int(opts["diagnose_max_unknowns"]):
        min_eig = tangent_eigenvalue(model, u, lam, p_ref)
        reason += _stall_diagnosis(min_eig, tangent_eigenvalue(model, u_start, 0.0, p_ref))
    timing = dict(model.timing)
    timing["wall_s"] = time.perf_counter() - t_start
    return PathResult(
        u=u[: model.n].copy(),
        lam=lam,
        status=status,
        reason=reason,
        iterations=iters,
        steps=steps,
        cutbacks=cuts,
        history=history,
        timing=timing,
        state=u,
        min_eigenvalue=min_eig,
    )
