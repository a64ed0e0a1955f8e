"""A unit's bending stiffness as a function of both chamber pressures, by FEA at prescribed end rotations.

The unit model (`workflow.actuator.unit_model`) joins a unit's free angle theta_f(P) and blocked moment M_b(P) by a
spring of stiffness k = M_b / theta_f (the secant). On the diagonal P_T = P_B both vanish and the secant is 0/0: the
model then takes the secant at a nearby pair, an estimate nobody had measured. That is where the paper's plans hold a
group (Table 8's DIP group at P_T = P_B), so it matters what co-pressurising does.

The reference is the one the end hold was chosen against (`workflow.actuator.moment_check`): a unit inside a longer
actuator, the middle unit of a chain of ``chain_units`` chambers cut at gap centres. The chain's end is held at
end rotations of +delta and -delta per unit (total n * delta) about the blocked state; the end couple M is the
moment every unit carries, and the middle unit's backbone rotation theta_mid its response:

    k(P) = (M(-delta) - M(+delta)) / (theta_mid(+delta) - theta_mid(-delta))     (N m per degree, per unit)

M is positive in the sense of P_T bending, so it falls as the end is rotated further that way. Angles in degrees
per unit, moments in N m for the full actuator width, pressures in kPa.

`StiffnessTable` turns the measured pairs into a model of k over both pressures: the unit is its own mirror across
the paper layer, so k(P_T, P_B) = k(P_B, P_T) and the pairs are folded onto P_T >= P_B; log k is interpolated
linearly over their triangulation (k spans 30x between rest and co-pressure, so the logarithm keeps the
interpolant positive and the relative error even). No extrapolation: outside the measured pairs' hull, and where the
middle unit locked (no finite k), the table gives NaN. `heldout_errors` checks it on pairs not used to build it.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import xarray as xr
from scipy.interpolate import LinearNDInterpolator

from workflow import fem
from workflow.actuator.moment_check import unit_rotations_deg
from workflow.actuator.unit_model import UnitModel
from workflow.common.constants import SOLVER_STATUS

__all__ = [
    "DEFAULT_STIFFNESS",
    "SOLVES",
    "StiffnessTable",
    "compare_model",
    "heldout_errors",
    "rotation_stiffness",
    "stiffness_dataset",
]

log = logging.getLogger(__name__)

#: Points of the study (config ``actuator.stiffness``).
DEFAULT_STIFFNESS = {
    "delta_deg": 3.0,  # chain end rotation per unit on either side of the blocked state
    "chain_units": 5,
    # the table's pairs: the diagonal and 20 kPa off it, where the unit model uses the table
    "pairs_kpa": [[0.0, 0.0], [50.0, 50.0], [100.0, 100.0], [200.0, 200.0], [300.0, 300.0], [20.0, 0.0]]
    + [[110.0, 90.0], [210.0, 190.0], [300.0, 280.0]],
    "heldout_kpa": [],  # pairs left out of the table, to verify it
}

#: The solves per pressure pair, in order: (name, unit-model case, end rotation in units of delta).
SOLVES = (("free", "free", 0.0), ("blocked", "blocked", 0.0), ("plus", "rotation", 1.0), ("minus", "rotation", -1.0))


def rotation_stiffness(
    chain: fem.UnitMesh,
    pairs_kpa: Sequence[Sequence[float]],
    *,
    delta_deg: float = 3.0,
    actuator: Mapping | None = None,
    solve_kwargs: Mapping | None = None,
) -> dict[str, np.ndarray]:
    """FEA of the chain at each pressure pair: free, blocked and end rotations of +-``delta_deg`` per unit.

    ``chain``: a `workflow.actuator.moment_check.chain_mesh` (cut at gap centres, so its ends are the backbone alone). With ``actuator`` (the
    config section) every solve takes its material, contact, solver and restarts
    (`workflow.fem.solve_unit_from_config`); without it `workflow.fem.solve_unit` with ``solve_kwargs``. Returns
    arrays over (pair, solve) of ``status``, ``load_factor``, ``moment_nm``, ``mid_angle_deg`` (the middle unit's
    rotation), ``wall_time_s``, and over pair ``k_nm_per_deg`` (NaN unless both rotations converged and the middle
    unit turned with the end: at high co-pressure the walls pressed across its gaps can lock it, and the chain's end
    strips then take the whole rotation).
    """
    if not delta_deg > 0:
        raise ValueError(f"delta_deg = {delta_deg}: must be > 0")
    if not chain.end_gaps:
        raise ValueError("rotation_stiffness needs a chain cut at gap centres (chain_mesh), not the unit model")
    kw = dict(solve_kwargs or {})
    n = int(chain.geometry["n_chambers"])
    P = np.asarray(pairs_kpa, float).reshape(-1, 2)
    shape = (len(P), len(SOLVES))
    out = {k: np.full(shape, np.nan) for k in ("load_factor", "moment_nm", "mid_angle_deg", "wall_time_s")}
    out["status"] = np.full(shape, -1, dtype=np.int8)
    for i, (pt, pb) in enumerate(P):
        for j, (name, case, sign) in enumerate(SOLVES):
            t0 = time.perf_counter()
            common = {"end_angle_deg": sign * delta_deg * n, "keep_displacement": True}
            if actuator is not None:
                r = fem.solve_unit_from_config(actuator, chain.dim, pt, pb, case, mesh=chain, **common, **kw)
            else:
                r = fem.solve_unit(chain, pt, pb, case=case, **common, **kw)
            out["status"][i, j] = r.status
            out["load_factor"][i, j] = r.load_factor
            out["mid_angle_deg"][i, j] = unit_rotations_deg(chain, r.displacement)[n // 2]
            out["moment_nm"][i, j] = 0.0 if case == "free" else r.bending_moment_nm
            out["wall_time_s"][i, j] = time.perf_counter() - t0
            log.info(
                "stiffness: P = (%g, %g) kPa, %s: status %d at %.3f of the load, middle unit %.3f deg, M %.5f N m, "
                "%.1f s",
                pt,
                pb,
                name,
                r.status,
                r.load_factor,
                out["mid_angle_deg"][i, j],
                out["moment_nm"][i, j],
                out["wall_time_s"][i, j],
            )
    j = {name: k for k, (name, _, _) in enumerate(SOLVES)}
    both = (out["status"][:, j["plus"]] == 0) & (out["status"][:, j["minus"]] == 0)
    dth = out["mid_angle_deg"][:, j["plus"]] - out["mid_angle_deg"][:, j["minus"]]
    with np.errstate(divide="ignore", invalid="ignore"):
        k = (out["moment_nm"][:, j["minus"]] - out["moment_nm"][:, j["plus"]]) / dth
    out["k_nm_per_deg"] = np.where(both & (dth > 0), k, np.nan)
    out["pairs_kpa"] = P
    return out


@dataclass(frozen=True)
class StiffnessTable:
    """k(P_T, P_B) in N m per degree per unit from measured pairs (kPa), symmetric in its two pressures.

    Callable like the unit model's surrogates: ``table(p_top_kpa, p_bottom_kpa)`` broadcasts and returns NaN outside
    the hull of the finite pairs (folded onto P_T >= P_B). Pairs with a NaN or non-positive k (a locked middle unit,
    a failed solve) are left out.
    """

    p_top_kpa: np.ndarray
    p_bottom_kpa: np.ndarray
    k_nm_per_deg: np.ndarray
    _interp: LinearNDInterpolator = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        pt, pb, k = (np.asarray(a, float).ravel() for a in (self.p_top_kpa, self.p_bottom_kpa, self.k_nm_per_deg))
        if not (pt.size == pb.size == k.size):
            raise ValueError("p_top_kpa, p_bottom_kpa and k_nm_per_deg must have one value per pair")
        ok = np.isfinite(k) & (k > 0)
        hi, lo = np.maximum(pt, pb)[ok], np.minimum(pt, pb)[ok]
        pts, idx = np.unique(np.column_stack([hi, lo]), axis=0, return_index=True)
        if len(pts) < 3 or np.linalg.matrix_rank(pts - pts.mean(axis=0)) < 2:
            raise ValueError(
                f"a stiffness table needs three pairs with a finite k that span both pressures, got {len(pts)}"
            )
        object.__setattr__(self, "_interp", LinearNDInterpolator(pts, np.log(k[ok][idx])))

    def __call__(self, p_top_kpa, p_bottom_kpa) -> np.ndarray:
        pt, pb = np.broadcast_arrays(np.asarray(p_top_kpa, float), np.asarray(p_bottom_kpa, float))
        k = np.exp(self._interp(np.maximum(pt, pb).ravel(), np.minimum(pt, pb).ravel())).reshape(pt.shape)
        return k if k.ndim else k[()]

    @classmethod
    def from_study(cls, ds: xr.Dataset) -> "StiffnessTable":
        """The table of a ``unit_stiffness.nc`` (its fit pairs only, when it marks held-out ones)."""
        use = ds["fit"].values.astype(bool) if "fit" in ds else np.ones(ds.sizes["pair"], bool)
        return cls(ds["p_top_kpa"].values[use], ds["p_bottom_kpa"].values[use], ds["k_nm_per_deg"].values[use])


def heldout_errors(
    table: StiffnessTable, p_top_kpa, p_bottom_kpa, k_fea_nm_per_deg, delta_deg: float, m_blocked_max_nm: float
) -> dict[str, np.ndarray]:
    """The table against FEA pairs not used to build it.

    Returns ``k_table_nm_per_deg``, ``rel_error`` (table / FEA - 1) and ``moment_error_share``: the error in the end
    moment over the study's window, |k_table - k_FEA| * delta, as a share of the largest blocked moment of the grid
    (``m_blocked_max_nm``, N m): how far a moment predicted within +-delta of the blocked state is off, measured
    against the moments the unit delivers.
    """
    k_fea = np.asarray(k_fea_nm_per_deg, float)
    k_tab = np.asarray(table(p_top_kpa, p_bottom_kpa), float)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = k_tab / k_fea - 1.0
    share = np.abs(k_tab - k_fea) * float(delta_deg) / float(m_blocked_max_nm)
    return {"k_table_nm_per_deg": k_tab, "rel_error": rel, "moment_error_share": share}


def compare_model(res: Mapping[str, np.ndarray], model: UnitModel) -> dict[str, np.ndarray]:
    """The unit model's stiffness (its secant, or the offset estimate near P_T = P_B) at the study's pairs, and its
    error against the FEA as a share of the FEA's value."""
    P = np.asarray(res["pairs_kpa"])
    k_model = np.asarray(model.stiffness_nm_per_deg(P[:, 0], P[:, 1]), float)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = k_model / res["k_nm_per_deg"] - 1.0
    return {"k_model_nm_per_deg": k_model, "k_model_rel_error": rel}


def stiffness_dataset(
    res: Mapping[str, np.ndarray],
    *,
    delta_deg: float,
    h_mm: float,
    chain_units: int,
    model: Mapping[str, np.ndarray] | None = None,
    fit: np.ndarray | None = None,
    table: Mapping[str, np.ndarray] | None = None,
    m_blocked_max_nm: float | None = None,
    model_with_table: Mapping[str, np.ndarray] | None = None,
) -> xr.Dataset:
    """``unit_stiffness.nc`` content from :func:`rotation_stiffness` (and :func:`compare_model`), no provenance.

    ``fit`` marks the pairs the `StiffnessTable` was built on (the others are held out); ``table`` is
    :func:`heldout_errors` at every pair, ``m_blocked_max_nm`` its moment scale; ``model_with_table`` is
    :func:`compare_model` of the unit model that takes the table inside its window."""
    P = np.asarray(res["pairs_kpa"])
    dims = ("pair", "solve")
    flag_vals = np.array(sorted(SOLVER_STATUS), dtype="i1")
    ds = xr.Dataset(
        {
            "p_top_kpa": ("pair", P[:, 0], {"units": "kPa", "long_name": "top chamber pressure"}),
            "p_bottom_kpa": ("pair", P[:, 1], {"units": "kPa", "long_name": "bottom chamber pressure"}),
            "mid_angle_deg": (
                dims,
                res["mid_angle_deg"],
                {"units": "degree", "long_name": "backbone rotation of the chain's middle unit"},
            ),
            "moment_nm": (dims, res["moment_nm"], {"units": "N m", "long_name": "end couple per unit (0 when free)"}),
            "status": (
                dims,
                res["status"],
                {
                    "units": "1",
                    "long_name": "solver status",
                    "flag_values": flag_vals,
                    "flag_meanings": " ".join(SOLVER_STATUS[int(v)] for v in flag_vals),
                },
            ),
            "load_factor": (dims, res["load_factor"], {"units": "1", "long_name": "share of the load reached"}),
            "wall_time_s": (dims, res["wall_time_s"], {"units": "s", "long_name": "wall time of the solve"}),
            "k_nm_per_deg": (
                "pair",
                res["k_nm_per_deg"],
                {"units": "N m / degree", "long_name": "bending stiffness of a unit inside the chain (FEA)"},
            ),
        },
        coords={"solve": [s[0] for s in SOLVES]},
    )
    # the unit model's stiffness as it stands and with the table inside its window (compare_model of each)
    for key, cmp, what in (
        ("k_model", model, "unit model's stiffness (secant; offset estimate near P_T = P_B)"),
        ("k_model_table", model_with_table, "unit model's stiffness with the table inside its window"),
    ):
        if cmp is not None:
            ds[f"{key}_nm_per_deg"] = ("pair", cmp["k_model_nm_per_deg"], {"units": "N m / degree", "long_name": what})
            ds[f"{key}_rel_error"] = (
                "pair",
                cmp["k_model_rel_error"],
                {"units": "1", "long_name": f"{what} / FEA's - 1"},
            )
    if fit is not None:
        ds["fit"] = ("pair", np.asarray(fit, bool), {"long_name": "pair used to build the stiffness table"})
    if table is not None:
        ds["k_table_nm_per_deg"] = (
            "pair",
            table["k_table_nm_per_deg"],
            {"units": "N m / degree", "long_name": "stiffness table (log-linear over the fit pairs, symmetric)"},
        )
        ds["k_table_rel_error"] = ("pair", table["rel_error"], {"units": "1", "long_name": "table / FEA - 1"})
        ds["k_table_moment_error_share"] = (
            "pair",
            table["moment_error_share"],
            {"units": "1", "long_name": "|k_table - k_FEA| delta / the grid's largest blocked moment"},
        )
        held = ~np.asarray(fit, bool) if fit is not None else np.zeros(len(P), bool)
        share = np.asarray(table["moment_error_share"], float)[held]
        ds.attrs["m_blocked_max_nm"] = float(m_blocked_max_nm)
        ds.attrs["heldout_moment_error_share_max"] = float(np.nanmax(share)) if np.isfinite(share).any() else np.nan
    ds.attrs.update(
        delta_deg=float(delta_deg),
        h_mm=float(h_mm),
        chain_units=int(chain_units),
        method="k = (M(-delta) - M(+delta)) / (theta_mid(+delta) - theta_mid(-delta)), chain end held at "
        "+-delta per unit, theta_mid the middle unit's rotation",
    )
    return ds
