"""Config checks beyond the JSON Schema, and loading a config outside Snakemake.

The schema (config/schema.yaml) catches unknown keys, wrong types and
out-of-range values; :func:`check_config` adds what needs cross references
(patient measurement codes that have no anthropometry or name another finger,
implausible coded levels, pressure bounds beyond the material limit or the
sweeps, unstable hyperelastic constants, a missing table file), so every
mistake is reported before any job starts.
"""

from __future__ import annotations

import copy
import logging
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import yaml

from workflow.cascade.finger import patient_dimensions_mm
from workflow.cascade.model import unit_section
from workflow.doe import ccd as doe
from workflow.fem.material_stability import drucker_instabilities
from workflow.layout.search import candidate_layouts
from workflow.musculoskeletal.patient_loads import patient_levels

__all__ = ["ConfigError", "check_config", "checked_patients", "load_config", "REPO_ROOT", "SCHEMA_PATH"]

REPO_ROOT = Path(__file__).resolve().parents[1]
SCHEMA_PATH = REPO_ROOT / "config" / "schema.yaml"


class ConfigError(ValueError):
    """A config value that is well-typed but wrong; the message names the key."""


log = logging.getLogger(__name__)


def check_config(config: Mapping[str, Any]) -> list[str]:
    """Raise :class:`ConfigError` naming the first offending key; return the warnings.

    Warnings: a patient outside the design region (computed, flagged in its
    outputs), hyperelastic constants unstable only beyond stretches 0.5-2.
    """
    warnings: list[str] = []
    anth = config["anthropometry"]["measures"]
    if "scaling" not in config:
        raise ConfigError("config key 'scaling' is missing (OpenSim scale-factor model per body and axis)")
    for body, axes in config["scaling"].items():
        for axis, spec in axes.items():
            for code in spec["weights"]:
                if code not in anth:
                    raise ConfigError(f"scaling.{body}.{axis}.weights.{code}: no anthropometry for {code}")
    for name, patient in config["patients"].items():
        finger = str(patient.get("finger", "F3"))
        for code, value in patient.get("measurements_mm", {}).items():
            # Table 2 codes: D/B/L (depth, breadth, length), the finger's digit, the site
            if code[1:2] != finger[1:]:
                raise ConfigError(
                    f"patients.{name}.measurements_mm.{code}: a finger-{code[1:2]} measure, but patients.{name}.finger "
                    f"is {finger}; give that finger's codes ({code[0]}{finger[1:]}{code[2:]}, ...) or coded levels"
                )
            if code not in anth:
                raise ConfigError(f"patients.{name}.measurements_mm.{code}: no anthropometry (mean, SD) for this code")
            if not value > 0:
                raise ConfigError(f"patients.{name}.measurements_mm.{code} = {value}: must be > 0 mm")
        warnings += _check_coded_levels(name, patient, config["anthropometry"])
    _check_pressure_bounds(config)
    geom = config.get("actuator", {}).get("geometry", {})
    fillet = float(geom.get("fillet", 0.0))
    room = min(float(geom.get("ac_th_for", 2.0)), float(geom.get("ac_th_up", 2.0)))
    if fillet > room:
        raise ConfigError(
            f"actuator.geometry.fillet = {fillet:g} mm: larger than the block's wall and roof round the pocket "
            f"(min(ac_th_for, ac_th_up) = {room:g} mm)"
        )
    warnings += _check_material(config.get("actuator", {}).get("material", {}))
    cascade = config.get("cascade", {})
    for key in ("validation_patient", "dummy_patient"):
        name = cascade.get(key)
        if name and name not in config["patients"]:
            raise ConfigError(f"cascade.{key} = {name!r}: no such patient (patients: {sorted(config['patients'])})")
    cal = cascade.get("calibration", {})
    name = cal.get("patient")
    if name and name not in config["patients"]:
        raise ConfigError(
            f"cascade.calibration.patient = {name!r}: no such patient (patients: {sorted(config['patients'])})"
        )
    for key in ("gain_bounds", "compliance_bounds_rad_per_nm"):
        lo_hi = cal.get(key)
        if lo_hi is not None and not float(lo_hi[0]) < float(lo_hi[1]):
            raise ConfigError(f"cascade.calibration.{key} = {list(lo_hi)}: the lower bound must be below the upper")
    dummy = cascade.get("dummy_patient")
    if dummy and config["patients"][dummy].get("model", "human") != "dummy":
        raise ConfigError(f"cascade.dummy_patient = {dummy!r}: that patient needs `model: dummy`")
    checked_patients(config)  # raises on a name that is no patient
    _check_layout(config)
    fid = config.get("fidelity", {})
    for ex in fid.get("check", {}).get("exercises", []):
        if ex not in config["exercises"]:
            raise ConfigError(
                f"fidelity.check.exercises: {ex!r} is no exercise (exercises: {sorted(config['exercises'])})"
            )
    for k, case in enumerate(fid.get("fem_cases", [])):
        models = {c["model"] for c in fid["fem_cases"] if c["contact"]}
        if case["model"] not in models:
            raise ConfigError(
                f"fidelity.fem_cases[{k}]: model {case['model']} has no case with contact "
                "(the finest with contact is the reference)"
            )
    ms = config.get("musculoskeletal", {})
    if ms.get("backend", "table") == "table":
        path = Path(ms.get("table_path", ""))
        if not path.is_file():
            raise ConfigError(
                f"musculoskeletal.table_path = {str(path)!r}: file not found "
                "(the table backend needs an OpenSim export in the authors' CSV format)"
            )
    return warnings


def _fingertip_mm(patient: Mapping[str, Any], anthropometry: Mapping[str, Any]) -> float:
    """The fingertip's distance from the MCP joint on the straight finger, mm: the sum of the patient's phalanx
    lengths, as :func:`workflow.cascade.finger.build_finger` places it (``tip_x_m``)."""
    measures, sd = anthropometry["measures"], float(anthropometry.get("coded_unit_sd", 1.0))
    dims = patient_dimensions_mm(measures, patient_levels(patient, measures, sd), sd, patient.get("measurements_mm"))
    return dims["L3PP"] + dims["L3MP"] + dims["L3DP"]


def _check_coded_levels(name: str, patient: Mapping[str, Any], anthropometry: Mapping[str, Any]) -> list[str]:
    """Error beyond ``anthropometry.coded_bound``; a warning outside the CCD's design region (sphere and box)."""

    x = patient_levels(patient, anthropometry["measures"], float(anthropometry.get("coded_unit_sd", 1.0)))
    given = f"patients.{name}.coded" if "coded" in patient else f"patients.{name}.measurements_mm"
    levels = ", ".join(f"{f} {v:.3g}" for f, v in x.items())
    bound = float(anthropometry.get("coded_bound", 3.0))
    far = [f for f, v in x.items() if not abs(v) <= bound]  # NaN counts as far
    if far:
        raise ConfigError(
            f"{given}: coded levels ({levels}) beyond the plausible bound |x| <= {bound:g} "
            f"(anthropometry.coded_bound) in {', '.join(far)}: no finger of Table 2's population"
        )
    flags = doe.design_region_flags(x)
    if flags["in_sphere"] and flags["in_box"]:
        return []
    return [
        f"{given}: coded levels ({levels}, ||x|| = {np.linalg.norm(list(x.values())):.3g}) lie outside the "
        "design region (||x|| <= 1, |x_i| <= 1, Tables 3-4): the response surfaces extrapolate; the outputs "
        "flag it (in_design_range = False)"
    ]


def _check_pressure_bounds(config: Mapping[str, Any]) -> None:
    """No configured pressure above the material limit; no plan beyond the sweep its surrogate was fitted on."""
    mat = config.get("actuator", {}).get("material", {})
    limit = float(mat.get("p_limit_kpa", 300.0))
    source = mat.get("p_limit_source", "Chung & Venter 2024, Fig. 11: the largest pressure considered")
    sweep, cascade, stab = config.get("sweep", {}), config.get("cascade", {}), config.get("stability", {})
    act = config.get("actuator", {})
    pressures = [(f"sweep.{m}.p_max_kpa", sweep.get(m, {}).get("p_max_kpa")) for m in ("2d", "3d")]
    pressures += [
        ("cascade.p_max_kpa", cascade.get("p_max_kpa")),
        ("stability.rays.p_max_kpa", stab.get("rays", {}).get("p_max_kpa")),
        ("stability.locking.p_top_kpa", stab.get("locking", {}).get("p_top_kpa")),
    ]
    pressures += [
        (f"actuator.unit_check.p_top_kpa[{i}]", p) for i, p in enumerate(act.get("unit_check", {}).get("p_top_kpa", []))
    ]
    pressures += [
        (f"actuator.moment_check.pairs_kpa[{i}]", max(p))
        for i, p in enumerate(act.get("moment_check", {}).get("pairs_kpa", []))
    ]
    pressures += [
        (f"actuator.stiffness.pairs_kpa[{i}]", max(p))
        for i, p in enumerate(act.get("stiffness", {}).get("pairs_kpa", []))
    ]
    pressures += [
        (f"fidelity.p_top_kpa[{i}]", p) for i, p in enumerate(config.get("fidelity", {}).get("p_top_kpa", []))
    ]
    pressures += [
        (f"cascade.calibration.fit_pressures_2d_kpa[{i}]", max(p))
        for i, p in enumerate(cascade.get("calibration", {}).get("fit_pressures_2d_kpa", []))
    ]
    for key, p in pressures:
        if p is not None and not float(p) <= limit:
            raise ConfigError(
                f"{key} = {float(p):g} kPa exceeds actuator.material.p_limit_kpa = {limit:g} kPa "
                f"({source}): no chamber may be asked for more than the silicone bears"
            )
    fea = cascade.get("surrogate", "3d")
    p_plan, p_sampled = cascade.get("p_max_kpa"), sweep.get(fea, {}).get("p_max_kpa")
    if p_plan is not None and p_sampled is not None and float(p_plan) > float(p_sampled):
        raise ConfigError(
            f"cascade.p_max_kpa = {float(p_plan):g} kPa exceeds sweep.{fea}.p_max_kpa = "
            f"{float(p_sampled):g} kPa, the range the cascade.surrogate ({fea}) was sampled on: "
            "plans would stand on extrapolated unit responses"
        )


def _check_material(material: Mapping[str, Any]) -> list[str]:
    """mu0 > 0 and Drucker stability of the Table 5 law (:mod:`workflow.fem.material_stability`)."""

    c = {
        k: float(material.get(k, d))
        for k, d in (("c10_mpa", 0.26056762), ("c01_mpa", 0.09754981), ("c20_mpa", 0.05750069))
    }
    consts = ", ".join(f"{k} = {v:g}" for k, v in c.items())
    mu0 = 2.0 * (c["c10_mpa"] + c["c01_mpa"])
    if not mu0 > 0:
        raise ConfigError(
            f"actuator.material: {consts} MPa give the initial shear modulus mu0 = 2 (c10 + c01) = "
            f"{mu0:g} MPa <= 0: the Mooney-Rivlin law is unstable at rest (Table 5 has c10 = 0.26057)"
        )
    found = drucker_instabilities(c["c10_mpa"], c["c01_mpa"], c["c20_mpa"])
    bad = [str(i) for i in found if i.within]
    if bad:
        raise ConfigError(
            f"actuator.material: {consts} MPa are not Drucker-stable within stretches 0.5-2: {'; '.join(bad)}"
        )
    return [f"actuator.material: {consts} MPa: {i} (outside stretches 0.5-2, inside 0.3-3)" for i in found]


def load_config(*paths: str | Path, validate: bool = True) -> dict[str, Any]:
    """Merge YAML configs left to right (as ``--configfile`` does), fill schema defaults and check.

    For tests and notebooks; Snakemake itself validates in rules/common.smk.
    """
    config: dict[str, Any] = {}
    for p in paths:
        _merge(config, yaml.safe_load(Path(p).read_text()) or {})
    if validate:
        from snakemake.utils import validate as sm_validate

        sm_validate(config, str(SCHEMA_PATH))
        for w in check_config(config):
            log.warning(w)
    return config


def _merge(a: dict, b: Mapping) -> None:
    for k, v in b.items():
        if isinstance(v, Mapping) and isinstance(a.get(k), dict):
            _merge(a[k], v)
        else:
            a[k] = copy.deepcopy(v)


def checked_patients(config: Mapping[str, Any]) -> list[str]:
    """The patients whose plans the default run checks by FEA (config ``fea_check.patients``).

    ``null`` (the default): the validation patient and the dummy (the paper's PLA finger), those of them that are
    set; ``all``: every patient; else a list of patient names. Every other patient's check is a target of its own.
    """
    names = config.get("fea_check", {}).get("patients")
    patients = config["patients"]
    if names is None:
        cascade = config.get("cascade", {})
        names = [cascade.get(k) for k in ("validation_patient", "dummy_patient")]
        return list(dict.fromkeys(n for n in names if n and n in patients))
    if names == "all":
        return sorted(patients)
    for n in names:
        if n not in patients:
            raise ConfigError(f"fea_check.patients: {n!r} is no patient (patients: {sorted(patients)})")
    return list(dict.fromkeys(names))


def _check_layout(config: Mapping[str, Any]) -> None:
    """The layout design's patients exist and its bounds hold at least one and at most max_candidates layouts."""
    lay = config.get("layout") or {}
    for name in lay.get("patients", []):
        if name not in config["patients"]:
            raise ConfigError(f"layout.patients: {name!r} is no patient (patients: {sorted(config['patients'])})")
    if not lay.get("patients"):
        return
    if lay.get("use") and bool(lay["calibrated"]) != bool(config["cascade"]["calibration"]["use"]):
        raise ConfigError(
            f"layout.use with layout.calibrated = {lay['calibrated']} but cascade.calibration.use = "
            f"{config['cascade']['calibration']['use']}: the plans would stand on another chain than the one the "
            "layouts were chosen on; set both alike"
        )
    c = config["cascade"]
    sec = unit_section(c["unit_geometry_mm"])
    d = c["densities"]
    mass_g = (d["silicone"] * sec["silicone_mm3"] + d["paper"] * sec["paper_mm3"]) * 1e-6
    for name in dict.fromkeys(lay["patients"]):
        # the search job's overhang bound is measured from the patient's own fingertip
        tip_mm = _fingertip_mm(config["patients"][name], config["anthropometry"])
        try:
            n = len(
                candidate_layouts(
                    lay["bounds"],
                    unit_length_mm=sec["unit_length_mm"],
                    unit_mass_g=mass_g,
                    max_length_mm=float(lay["max_length_mm"]),
                    max_mass_g=float(lay["max_mass_g"]),
                    tip_mm=tip_mm,
                    max_overhang_mm=float(lay["max_overhang_mm"]),
                    layout_shift_mm=float(c.get("layout_shift_mm", 0.0)),
                    max_candidates=int(lay["max_candidates"]),
                )
            )
        except ValueError as err:
            raise ConfigError(f"{str(err).replace('layout bounds', 'layout.bounds')} (patient {name})") from None
        if int(lay["confirm_top"]) > n:
            raise ConfigError(
                f"layout.confirm_top = {lay['confirm_top']}: the bounds hold only {n} layouts for patient {name}"
            )
