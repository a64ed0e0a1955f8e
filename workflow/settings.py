"""Config checks beyond the JSON Schema, and loading a config outside Snakemake.

The schema (config/schema.yaml) catches unknown keys, wrong types and
out-of-range values; :func:`check_config` adds what needs cross references
(patient measurement codes that have no anthropometry, a missing table file),
so every mistake is reported before any job starts.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any, Mapping

import yaml

__all__ = ["ConfigError", "check_config", "load_config", "REPO_ROOT", "SCHEMA_PATH"]

REPO_ROOT = Path(__file__).resolve().parents[1]
SCHEMA_PATH = REPO_ROOT / "config" / "schema.yaml"


class ConfigError(ValueError):
    """A config value that is well-typed but wrong; the message names the key."""


def check_config(config: Mapping[str, Any]) -> None:
    """Raise :class:`ConfigError` naming the first offending key."""
    anth = config["anthropometry"]["measures"]
    if "scaling" not in config:
        raise ConfigError("config key 'scaling' is missing (OpenSim scale-factor model per body and axis)")
    for body, axes in config["scaling"].items():
        for axis, spec in axes.items():
            for code in spec["weights"]:
                if code not in anth:
                    raise ConfigError(f"scaling.{body}.{axis}.weights.{code}: no anthropometry for {code}")
    for name, patient in config["patients"].items():
        for code, value in patient.get("measurements_mm", {}).items():
            if code not in anth:
                raise ConfigError(f"patients.{name}.measurements_mm.{code}: no anthropometry (mean, SD) for this code")
            if not value > 0:
                raise ConfigError(f"patients.{name}.measurements_mm.{code} = {value}: must be > 0 mm")
    cascade = config.get("cascade", {})
    for key in ("validation_patient", "dummy_patient"):
        name = cascade.get(key)
        if name and name not in config["patients"]:
            raise ConfigError(f"cascade.{key} = {name!r}: no such patient (patients: {sorted(config['patients'])})")
    dummy = cascade.get("dummy_patient")
    if dummy and config["patients"][dummy].get("model", "human") != "dummy":
        raise ConfigError(f"cascade.dummy_patient = {dummy!r}: that patient needs `model: dummy`")
    fid = config.get("fidelity", {})
    for ex in fid.get("check", {}).get("exercises", []):
        if ex not in config["exercises"]:
            raise ConfigError(f"fidelity.check.exercises: {ex!r} is no exercise (exercises: {sorted(config['exercises'])})")
    for k, case in enumerate(fid.get("fem_cases", [])):
        models = {c["model"] for c in fid["fem_cases"] if c["contact"]}
        if case["model"] not in models:
            raise ConfigError(f"fidelity.fem_cases[{k}]: model {case['model']} has no case with contact "
                              "(the finest with contact is the reference)")
    ms = config.get("musculoskeletal", {})
    if ms.get("backend", "table") == "table":
        path = Path(ms.get("table_path", ""))
        if not path.is_file():
            raise ConfigError(
                f"musculoskeletal.table_path = {str(path)!r}: file not found "
                "(the table backend needs an OpenSim export in the authors' CSV format)"
            )


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
        check_config(config)
    return config


def _merge(a: dict, b: Mapping) -> None:
    for k, v in b.items():
        if isinstance(v, Mapping) and isinstance(a.get(k), dict):
            _merge(a[k], v)
        else:
            a[k] = copy.deepcopy(v)
