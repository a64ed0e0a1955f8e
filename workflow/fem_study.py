"""One FE unit fidelity of the speed-accuracy study: the unit check at one mesh and contact switch.

Its own module (and rule input) so that a change to how the study is judged
(:mod:`workflow.fidelity_run`) does not rerun minutes of FEA.  Units: kPa,
deg, N m, s.
"""

from __future__ import annotations

import logging
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.provenance import write_dataset
from workflow.runlog import solved

__all__ = ["P_STUDY", "FemCase", "fem_cases", "case_actuator", "write_fem_case"]

log = logging.getLogger(__name__)

#: The study points: P_T in kPa at P_B = 0.
P_STUDY = (60.0, 180.0, 300.0)


@dataclass(frozen=True)
class FemCase:
    """One FE unit fidelity: model (``2d``/``3d``), element size (mm), self-contact."""

    model: str
    h_mm: float
    contact: bool

    @property
    def name(self) -> str:
        return f"fem_{self.model}_h{self.h_mm:g}_{'contact' if self.contact else 'nocontact'}"

    @classmethod
    def parse(cls, name: str) -> "FemCase":
        m = re.fullmatch(r"fem_(2d|3d)_h([0-9.]+)_(contact|nocontact)", name)
        if m is None:
            raise ValueError(f"not an FE case name: {name!r} (expected e.g. fem_2d_h1_contact)")
        return cls(m.group(1), float(m.group(2)), m.group(3) == "contact")


def fem_cases(spec: Sequence[Mapping]) -> list[FemCase]:
    """Cases of the config list ``[{model, h_mm: [...], contact}, ...]``, each once, in order."""
    out: list[FemCase] = []
    for s in spec:
        for h in s["h_mm"]:
            c = FemCase(str(s["model"]), float(h), bool(s["contact"]))
            if c not in out:
                out.append(c)
    return out


def case_actuator(actuator: Mapping, case: FemCase) -> dict:
    """The ``actuator`` config with the case's element size and contact switch."""
    mesh = dict(actuator.get("mesh", {}), **{f"h_{case.model}_mm": float(case.h_mm)})
    contact = dict(actuator.get("contact", {}), enabled=bool(case.contact))
    return dict(actuator, mesh=mesh, contact=contact)


def write_fem_case(case_name: str, out: str | Path, *, actuator: Mapping[str, Any], config_slice: Any,
                   p_top_kpa: Sequence[float] = P_STUDY, rule: str = "fidelity_fem") -> xr.Dataset:
    """Rule ``fidelity_fem``: the unit check of one case -> ``results/fidelity/fem/{case}.nc``.

    Free angle and blocked moment per unit at ``p_top_kpa`` (P_B = 0) with
    their wall times (:func:`workflow.fem.unit_check`, retries included).
    """
    from workflow import fem

    case = FemCase.parse(case_name)
    t0 = time.perf_counter()
    ds, _ = fem.unit_check(case_actuator(actuator, case), (case.model,), p_top_kpa)
    wall = time.perf_counter() - t0
    ds = ds.squeeze("model", drop=True)
    ds["case_wall_time_s"] = ((), wall, {"units": "s", "long_name": "wall time of both rays (free, blocked), retries included"})
    ds.attrs.update({"case": case.name, "model": case.model, "h_mm": case.h_mm, "contact": int(case.contact)})
    log.info("%s: free %s deg, blocked %s N m, status %s, %.1f s", case.name,
             np.round(ds["bending_angle_deg"].values, 3), np.round(ds["bending_moment_nm"].values, 4),
             ds["status"].values.ravel().tolist(), wall,
             extra=solved(int(np.count_nonzero(ds["status"].values)), n=int(ds["status"].size)))
    write_dataset(ds, out, rule=rule, config_slice=config_slice,
                  title=f"FE unit fidelity {case.name}: free angle and blocked moment at P_T = 60/180/300 kPa")
    return ds
