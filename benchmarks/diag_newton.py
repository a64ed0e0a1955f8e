"""Why does Newton take many iterations per load step with contact?  A diagnosis, not a test.

Runs the 2D unit (free, contact, P_B = 0) from 0 to ``--p`` kPa and records every
Newton iteration: the load factor, the residual norm (as the solver measures it)
and the set of active contact pairs (slave node, master facet).  Reports

* steps accepted, cut-backs, iterations, and the median iterations per accepted step;
* the share of iterations at which the active contact set changed from the previous
  iteration of the same step, and the median iterations of steps with and without
  such a change;
* what changed: slaves entering or leaving contact, or switching master facet; how many enter already
  penetrating, and whether they came from inside a master facet's range (through the band) or from outside every
  facet's range (an edge);
* the observed convergence rate in the last iterations of each step,
  ``log(r_{k+1}) / log(r_k)`` on residuals normalised by the step's first one
  (2 for quadratic, 1 for linear convergence);
* the accuracy of the contact tangent at the final state: the finite-difference
  tangent the solver uses against a central difference with 10x and 100x larger
  steps (their spread bounds its error), relative Frobenius norm.

With ``--first-correction``: how far Newton's first correction from rest is from the solution, per element
technology and load factor (no contact): one linear solve at u = 0 (no line search), then the residual there over
the external load's norm (the solver's tolerance adds the reactions to it); then at one small load with the bulk
modulus and the paper's stiffness varied.  For an exactly linear problem the ratio is 0; the load at which it
reaches 1 is the scale below which a step from rest is in Newton's quadratic range.  ``--no-contact`` and
``--paper-e`` run the recorded ray without contact or with another paper stiffness.

    python benchmarks/diag_newton.py [--h 1.0] [--p 300] [--smoothing 0.05] [--no-contact] [--paper-e 120]
        -> benchmarks/out/diag_newton.json
    python benchmarks/diag_newton.py --first-correction  -> benchmarks/out/diag_first_correction.json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from workflow import fem  # noqa: E402
from workflow.fem import _solve  # noqa: E402

OUT = ROOT / "benchmarks" / "out"


def _slave_states(model, u, p_ref) -> dict:
    """(pair, slave) -> (inside a master facet's range, gap mm) for every slave."""
    x = model.positions(u, p_ref)
    out = {}
    for k, pair in enumerate(model.contacts):
        _, _, _, g, inside = pair._project(x)
        out.update({(k, int(s)): (bool(i), float(gg)) for s, i, gg in zip(pair.slave, inside, g)})
    return out


def _active_set(model, u, p_ref) -> frozenset:
    x = model.positions(u, p_ref)
    pairs = []
    for k, pair in enumerate(model.contacts):
        m, _, _, g, inside = pair._project(x)
        act = inside & (np.abs(g) <= pair.search) & (g < pair.smoothing)
        pairs += [(k, int(s), int(f), round(float(gg), 6)) for s, f, gg in zip(pair.slave[act], m[act], g[act])]
    return frozenset(pairs)


def _tangent_spread(model, u, p_ref) -> dict:
    """The solver's FD contact tangent against the same difference with 10x and 100x the step."""
    x = model.positions(u, p_ref)
    out = {}
    for pair in model.contacts:
        m, _, _, g, inside = pair._project(x)
        act = inside & (np.abs(g) <= pair.search) & (g < pair.smoothing)
        if not act.any():
            continue
        ma = m[act]
        nodes = np.concatenate([pair.slave[act, None], pair._nodes_2d(ma)], axis=1)
        lim = (pair.lo[ma], pair.hi[ma], pair.prev[ma] >= 0, pair.next[ma] >= 0)
        X = x[:, nodes].transpose(1, 2, 0)
        w = model.penalty * pair.penalty_factor * pair.area[act]
        nc = X.shape[0]
        nd = X.shape[1] * X.shape[2]
        Ks = {}
        for mult in (1.0, 10.0, 100.0):
            step = mult * 1e-7 * max(1.0, float(np.abs(X).max()))
            E = np.eye(nd) * step
            Xf = X.reshape(nc, -1)
            Xb = np.concatenate([Xf[None] + E[:, None, :], Xf[None] - E[:, None, :]])
            limb = tuple(np.tile(a, (2 * nd,) + (1,) * (a.ndim - 1)) for a in lim)
            fb = pair._local_force(Xb.reshape((-1,) + X.shape[1:]), np.tile(w, 2 * nd), limb)
            fb = fb.reshape(2, nd, nc, nd)
            Ks[mult] = ((fb[0] - fb[1]) / (2 * step)).transpose(1, 2, 0)
        ref = np.linalg.norm(Ks[1.0])
        out = {
            "n_active": int(nc),
            "rel_diff_10x": float(np.linalg.norm(Ks[10.0] - Ks[1.0]) / ref),
            "rel_diff_100x": float(np.linalg.norm(Ks[100.0] - Ks[1.0]) / ref),
        }
        break
    return out


def first_correction(h: float, p_kpa: float, formulations, lams, material: dict | None = None) -> list[dict]:
    """Residual after one Newton correction from rest over the external load's norm, per formulation and lam.

    ``h`` element size (mm), ``p_kpa`` P_T at lam = 1 (kPa), ``material`` overrides of the unit's material (e.g.
    ``bulk_ratio``, ``paper_e_mpa``).  A correction that inverts an element is recorded with a NaN ratio."""
    from workflow.fem import build_unit_mesh
    from workflow.fem._unit import unit_model

    um = build_unit_mesh(None, h=h, dim=2)
    # the solver's own Newton iteration, stopped after its first correction (no line search)
    once = {**_solve.DEFAULT_SOLVER, "max_iter": 1, "line_search": False}
    rows = []
    for form in formulations:
        m = unit_model(um, p_kpa, 0.0, case="free", contact=False, formulation=form, material=material)
        for lam in lams:
            _, u1, _, _, info = _solve._newton(m, np.zeros(m.nstate), lam, um.mesh.p, once)
            r1, _, info1 = m.evaluate(u1, lam, um.mesh.p, tangent=False)
            # an inverted element: NaN
            norm = float("nan") if r1 is None else _solve._residual_norm(m, r1, info1, once)[0]
            du = u1[: m.n] - lam * m.uD
            rows.append(
                {
                    "formulation": form,
                    **dict(material or {}),
                    "p_top_kpa": lam * p_kpa,
                    "max_correction_mm": float(np.abs(du[: m.n]).max()),
                    "residual_over_load": norm / info["f_ext_norm"],
                }
            )
            print(rows[-1], flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--h", type=float, default=1.0, help="element size, mm")
    ap.add_argument("--p", type=float, default=300.0, help="P_T at the end of the ray, kPa")
    ap.add_argument("--smoothing", type=float, default=None, help="contact smoothing band, mm (default: the model's)")
    ap.add_argument("--out", default="diag_newton.json", help="file name under benchmarks/out/")
    ap.add_argument("--first-correction", action="store_true", help="only the first correction from rest")
    ap.add_argument("--no-contact", action="store_true", help="the ray without contact")
    ap.add_argument("--paper-e", type=float, default=None, help="paper layer's Young's modulus, MPa (default 1200)")
    args = ap.parse_args(argv)
    if args.first_correction:
        rows = first_correction(
            args.h, args.p, ("displacement", "mixed", "enhanced_paper", "enhanced"), (1e-5, 1e-4, 1e-3, 0.0125, 0.025)
        )
        # what the spike scales with: the bulk modulus (K / mu0) and the paper's stiffness, at one small load
        for bulk in (10.0, 100.0, 1000.0, 10000.0):
            for paper in (1200.0, 12.0):
                rows += first_correction(
                    args.h, args.p, ("enhanced_paper",), (1e-4,), {"bulk_ratio": bulk, "paper_e_mpa": paper}
                )
        OUT.mkdir(parents=True, exist_ok=True)
        (OUT / "diag_first_correction.json").write_text(json.dumps(rows, indent=2))
        return 0

    records: list[dict] = []
    orig = _solve.Model.evaluate

    def evaluate(self, u, lam, p_ref, tangent=True):
        r, K, info = orig(self, u, lam, p_ref, tangent)
        if tangent and r is not None:
            rr = self.T.T @ r
            ri = info["r_internal"]
            records.append(
                {
                    "lam": float(lam),
                    "norm": float(np.sqrt(rr @ rr + ri @ ri)),
                    "active": _active_set(self, u, p_ref),
                    "states": _slave_states(self, u, p_ref),
                    "u": u,
                    "p_ref": p_ref,
                    "model": self,
                }
            )
        return r, K, info

    _solve.Model.evaluate = evaluate
    try:
        t0 = time.perf_counter()
        copts = {} if args.smoothing is None else {"smoothing_mm": args.smoothing}
        mat = None if args.paper_e is None else {"paper_e_mpa": args.paper_e}
        res = fem.solve_unit(
            {"dim": 2, "h": args.h},
            args.p,
            0.0,
            case="free",
            contact=not args.no_contact,
            contact_options=copts,
            material=mat,
        )
        wall = time.perf_counter() - t0
    finally:
        _solve.Model.evaluate = orig

    # group the iterations by load step attempt: a new attempt starts when lam changes
    attempts: list[list[dict]] = []
    for rec in records:
        if not attempts or rec["lam"] != attempts[-1][0]["lam"]:
            attempts.append([])
        attempts[-1].append(rec)
    iters = np.array([int(h["iterations"]) for h in res.history])
    changed_steps, plain_steps, changes, n_it, rates = [], [], 0, 0, []
    rates_changed, rates_plain = [], []
    kinds = {"entered": 0, "left": 0, "switched_facet": 0}
    entry_gaps, exit_gaps = [], []
    how = {"through_band": 0, "from_outside_facet_range": 0}
    for att in attempts:
        for a, b in zip(att, att[1:]):
            sa = {(k, s): f for k, s, f, _ in a["active"]}
            sb = {(k, s): f for k, s, f, _ in b["active"]}
            gb = {(k, s): g for k, s, _, g in b["active"]}
            ga = {(k, s): g for k, s, _, g in a["active"]}
            entry_gaps += [gb[s] for s in sb.keys() - sa.keys()]
            for s in sb.keys() - sa.keys():
                if gb[s] < 0:  # entered already penetrating: from outside every facet's range, or through the band?
                    prev_inside, prev_g = a["states"].get(s, (False, np.inf))
                    how[("through_band" if prev_inside else "from_outside_facet_range")] += 1
            exit_gaps += [ga[s] for s in sa.keys() - sb.keys()]
            kinds["entered"] += len(sb.keys() - sa.keys())
            kinds["left"] += len(sa.keys() - sb.keys())
            kinds["switched_facet"] += sum(sa[s] != sb[s] for s in sa.keys() & sb.keys())
        ch = sum({x[:3] for x in a["active"]} != {x[:3] for x in b["active"]} for a, b in zip(att, att[1:]))
        changes += ch
        n_it += max(len(att) - 1, 0)
        (changed_steps if ch else plain_steps).append(len(att) - 1)
        r = np.array([a["norm"] for a in att]) / max(att[0]["norm"], 1e-300)
        if len(r) >= 3 and r[-2] < 1 and r[-3] < 1 and r[-2] > 0 and r[-1] > 0:
            rates.append(float(np.log(r[-1]) / np.log(r[-2])))
            (rates_changed if ch else rates_plain).append(rates[-1])
    last = records[-1]
    out = {
        "h_mm": args.h,
        "smoothing_mm": args.smoothing if args.smoothing is not None else fem.contact_band(fem.DEFAULT_CONTACT, 2),
        "p_top_kpa": args.p,
        "contact": not args.no_contact,
        "paper_e_mpa": args.paper_e,
        "status": int(res.status),
        "load_factor": float(res.load_factor),
        "angle_deg": float(res.bending_angle_deg),
        "wall_time_s": round(wall, 2),
        "accepted_steps": int(len(res.history)),
        "attempts": len(attempts),
        "cut_backs": len(attempts) - len(res.history),
        "iterations_total": int(sum(len(a) - 1 for a in attempts)),
        "median_iterations_per_accepted_step": float(np.median(iters)) if iters.size else float("nan"),
        "share_of_iterations_with_active_set_change": changes / max(n_it, 1),
        "median_iterations_steps_with_change": float(np.median(changed_steps)) if changed_steps else float("nan"),
        "median_iterations_steps_without_change": float(np.median(plain_steps)) if plain_steps else float("nan"),
        "median_final_rate": float(np.median(rates)) if rates else float("nan"),
        "median_final_rate_steps_without_change": float(np.median(rates_plain)) if rates_plain else float("nan"),
        "median_final_rate_steps_with_change": float(np.median(rates_changed)) if rates_changed else float("nan"),
        "active_set_changes_by_kind": kinds,
        # a slave that enters (or leaves) the band already penetrating jumps the force: the C1 law does not see it
        "entries_already_penetrating": int(np.sum(np.array(entry_gaps) < 0)),
        "penetrating_entries_by_previous_state": how,
        "entry_gap_mm_quantiles_5_50_95": np.quantile(entry_gaps, [0.05, 0.5, 0.95]).round(5).tolist()
        if entry_gaps
        else [],
        "exits_while_penetrating": int(np.sum(np.array(exit_gaps) < 0)),
        "exit_gap_mm_quantiles_5_50_95": np.quantile(exit_gaps, [0.05, 0.5, 0.95]).round(5).tolist()
        if exit_gaps
        else [],
        "iterations_of_failed_attempts": int(sum(len(a) - 1 for a in attempts) - iters.sum()),
        "contact_tangent": _tangent_spread(last["model"], last["u"], last["p_ref"]),
    }
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / args.out).write_text(json.dumps(out, indent=2))
    print(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
