"""Provenance attributes and netCDF writing shared by every stage.

Every dataset the workflow writes carries the contract's global attributes
(``config_sha256``, ``git_commit``, ``created_utc``, ``rule``,
``package_versions``) plus the CF globals ``Conventions``, ``title``,
``source`` and ``history``.  They are set here, once, at the end of a stage
(xarray drops attrs in most operations, so setting them earlier is wasted).

Reading goes through :func:`open_result`: a truncated or foreign file stops
the job with one line naming the file, what is wrong and the fix.
"""

from __future__ import annotations

import ast
import datetime as _dt
import hashlib
import json
import os
import subprocess
from fnmatch import fnmatch
from importlib import metadata
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import xarray as xr

__all__ = [
    "CorruptInputError",
    "open_result",
    "load_joblib",
    "contract_variables",
    "config_sha256",
    "git_commit",
    "package_versions",
    "provenance_attrs",
    "write_dataset",
    "code_files",
    "TRACKED_PACKAGES",
    "RECOVER",
    "CONTRACT_VARIABLES",
    "corrupt_input",
]

#: Distributions whose versions are recorded in every dataset.
TRACKED_PACKAGES = (
    "numpy",
    "scipy",
    "pandas",
    "xarray",
    "netCDF4",
    "statsmodels",
    "scikit-learn",
    "scikit-fem",
    "meshio",
    "snakemake",
    "opensim",
    "pypardiso",
    "finger-rehab-workflow",
)

_REPO_ROOT = Path(__file__).resolve().parents[2]

#: How to recover from a damaged result: every result is a rule's output.
RECOVER = "delete it and rerun: Snakemake recomputes it"

#: Minimum variables (data or coordinates) per result file, as the data contract lists them; matched on the
#: end of the path, so a file of the same name elsewhere (a test's, a user's) is not held to it.
CONTRACT_VARIABLES = {
    "*doe/ccd.nc": ("marker", "depth", "length", "breadth"),
    "*doe/scaling.nc": ("scale",),
    "*musculoskeletal/moments.nc": ("moment_nm",),
    "*musculoskeletal/rsm.nc": ("coef", "term_p_value", "r2", "adj_r2", "p_value", "selected"),
    "*patients/*/joint_loads.nc": (
        "x",
        "passive_moment_nm",
        "passive_moment_lo_nm",
        "passive_moment_hi_nm",
        "active_limit_nm",
        "in_design_range",
    ),
    "*actuator/unit_check.nc": ("bending_angle_deg", "bending_moment_nm", "max_penetration_mm", "wall_time_s"),
    "*actuator/sweep/*/shard*.nc": (
        "p_top_kpa",
        "p_bottom_kpa",
        "bending_angle_deg",
        "bending_moment_nm",
        "status",
        "newton_iterations",
        "wall_time_s",
        "ray",
        "ratio",
        "scale",
    ),
    "*actuator/response_[23]d.nc": (
        "p_top_kpa",
        "p_bottom_kpa",
        "bending_angle_deg",
        "bending_moment_nm",
        "status",
        "converged",
        "mirrored",
        "newton_iterations",
        "wall_time_s",
    ),
    "*actuator/surrogate_cv.nc": ("r2", "mae", "rmse", "fit_time_s", "predict_time_s"),
    "*actuator/mapping_2d3d.nc": ("pressure_3d_kpa", "pressure_2d_kpa"),
    "*patients/*/cascade_plan.nc": ("pressure_kpa", "target_angle_deg", "predicted_angle_deg", "achieved", "reason"),
    "*benchmarks/speed_accuracy.nc": ("wall_time_s", "error", "pareto"),
}


class CorruptInputError(OSError):
    """A result file that cannot be read, or is not what this workflow writes; the message is one line."""


def corrupt_input(path: str | os.PathLike, what: str) -> CorruptInputError:
    """The error for ``path``: '<file>: <what is wrong>; delete it and rerun: Snakemake recomputes it'."""
    return CorruptInputError(f"{path}: {what}; {RECOVER}")


def contract_variables(path: str | os.PathLike) -> tuple[str, ...]:
    """The variables the data contract requires of ``path`` (empty for files it does not list)."""
    p = Path(path).as_posix()
    return next((v for pattern, v in CONTRACT_VARIABLES.items() if fnmatch(p, pattern)), ())


def open_result(path: str | os.PathLike, required_vars: tuple[str, ...] | None = None) -> xr.Dataset:
    """A result netCDF file, loaded into memory (closed again), with its variables checked.

    ``required_vars`` defaults to the contract's (:func:`contract_variables`).
    A file that is truncated, not netCDF, or lacks a required variable raises
    :class:`CorruptInputError`; a missing file raises FileNotFoundError as usual.
    """
    if not Path(path).is_file():
        raise FileNotFoundError(f"{path}: no such result file")
    try:
        ds = xr.load_dataset(path)
    except Exception as err:  # netCDF4/HDF5 raise OSError, RuntimeError or ValueError for a damaged file
        detail = str(err).strip().splitlines()[0].split(". ")[0][:160] if str(err).strip() else type(err).__name__
        raise corrupt_input(
            path, f"not a readable netCDF file (truncated or not written by this workflow: {detail})"
        ) from err
    need = contract_variables(path) if required_vars is None else tuple(required_vars)
    missing = [v for v in need if v not in ds.variables]
    if missing:
        raise corrupt_input(
            path,
            f"lacks the variable(s) {', '.join(missing)} this workflow writes there "
            "(written by another version, or not by it)",
        )
    return ds


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, Mapping):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def config_sha256(config_slice: Any) -> str:
    """SHA-256 of the canonical JSON of the part of the config a rule uses."""
    text = json.dumps(_jsonable(config_slice), sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def git_commit() -> str:
    """Commit of the working tree the code runs from (``+dirty`` if modified), or ``unknown``."""
    env_commit = os.environ.get("FINGERFLOW_GIT_COMMIT")
    if env_commit:
        return env_commit
    try:
        sha = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=_REPO_ROOT, capture_output=True, text=True, timeout=10
        ).stdout.strip()
        if not sha:
            return "unknown"
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=_REPO_ROOT,
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
        return sha + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def package_versions(extra: tuple[str, ...] = ()) -> dict[str, str]:
    """Installed versions of the tracked distributions (missing ones are left out)."""
    out: dict[str, str] = {}
    for name in TRACKED_PACKAGES + tuple(extra):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    return out


def provenance_attrs(*, rule: str, config_slice: Any, title: str, source: str = "") -> dict[str, str]:
    """The global attributes of the data contract for one dataset."""
    now = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
    return {
        "Conventions": "CF-1.10",
        "title": title,
        "source": source or "finger-rehab-workflow (Chung & Venter 2024 pipeline)",
        "history": f"{now} rule {rule}: finger-rehab-workflow {package_versions().get('finger-rehab-workflow', '?')}",
        "config_sha256": config_sha256(config_slice),
        "git_commit": git_commit(),
        "created_utc": now,
        "rule": rule,
        "package_versions": json.dumps(package_versions(), sort_keys=True),
    }


def _encoding(ds: xr.Dataset) -> dict[str, dict[str, Any]]:
    enc: dict[str, dict[str, Any]] = {}
    for name, var in ds.data_vars.items():
        e: dict[str, Any] = {}
        if np.issubdtype(var.dtype, np.floating):
            e["_FillValue"] = np.nan
            e["zlib"] = True
            e["complevel"] = 4
        # Booleans need no entry: xarray stores them as int8 with a dtype attribute
        # and decodes them back to bool (an explicit dtype would defeat that).
        enc[name] = e
    for name, coord in ds.coords.items():
        if np.issubdtype(coord.dtype, np.floating):
            enc[name] = {"_FillValue": None}
    return enc


def write_dataset(
    ds: xr.Dataset, path: str | os.PathLike, *, rule: str, config_slice: Any, title: str, source: str = ""
) -> Path:
    """Attach provenance and write ``ds`` to ``path`` as netCDF4 atomically.

    The file appears only once complete (written to a temporary name, then
    renamed), so an interrupted job never leaves a half-written result.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ds = ds.copy()
    ds.attrs.update(provenance_attrs(rule=rule, config_slice=config_slice, title=title, source=source))
    tmp = path.with_name(path.name + ".part")
    ds.to_netcdf(tmp, engine="netcdf4", format="NETCDF4", encoding=_encoding(ds))
    os.replace(tmp, path)
    return path


def _module_file(pkg: Path, dotted: str) -> Path | None:
    """The source file of ``workflow.<dotted>`` (a module or a package's ``__init__``), or None."""
    p = pkg.joinpath(*dotted.split(".")) if dotted else pkg
    if p.with_suffix(".py").is_file():
        return p.with_suffix(".py")
    if (p / "__init__.py").is_file():
        return p / "__init__.py"
    return None


def _imported_modules(path: Path, dotted: str) -> set[str]:
    """Dotted names (relative to ``workflow``) of the package modules ``path`` imports, anywhere in it."""
    package = dotted if path.name == "__init__.py" else dotted.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: from the module's package upwards
                base = package.split(".") if package else []
                base = base[: len(base) - (node.level - 1)] if node.level > 1 else base
                mod = ".".join(base + ([node.module] if node.module else []))
                full = "workflow" + ("." + mod if mod else "")
            else:
                full = node.module or ""
            # `from M import n`: n may itself be a submodule of M
            names = [full] + [f"{full}.{a.name}" for a in node.names]
        else:
            continue
        for name in names:
            if name == "workflow" or name.startswith("workflow."):
                out.add(name[len("workflow.") :] if name != "workflow" else "")
    return out


def code_files(*modules: str) -> list[str]:
    """Source files a rule's ``workflow`` modules run, for rule inputs.

    Listing them as inputs makes Snakemake rerun a rule when the science it
    calls changes.  ``modules`` are dotted names relative
    to ``workflow`` (e.g. ``"doe"``, ``"fem"``: a package means its
    ``__init__``); each brings the package modules it imports, transitively
    (found by parsing, so lazy imports inside functions count), and the
    packages those live in.  So the unit-model rules that use ``fem`` do not
    rerun when only the finger-actuator model (``fem._coupled``) changes.
    """
    pkg = Path(__file__).resolve().parents[1]
    seen: dict[str, Path] = {}
    todo = ["common.provenance", *modules]
    while todo:
        dotted = todo.pop()
        if dotted in seen:
            continue
        f = _module_file(pkg, dotted)
        if f is None:
            if dotted in modules:
                raise FileNotFoundError(f"code_files: no module workflow.{dotted}")
            continue  # `from M import name` where name is not a module
        seen[dotted] = f
        parts = dotted.split(".") if dotted else []
        todo += [".".join(parts[:i]) for i in range(len(parts))]  # enclosing packages run on import
        todo += sorted(_imported_modules(f, dotted) - seen.keys())
    # Relative paths keep the DAG independent of where the clone lives.
    return sorted({os.path.relpath(f) for f in seen.values()})


def load_joblib(path: str | os.PathLike) -> Any:
    """The object in a joblib file this workflow wrote (trusted files only: joblib unpickles).

    A damaged file, or one that needs code this installation lacks, raises
    :class:`CorruptInputError`; what the object must be is the caller's check.
    """
    import warnings

    import joblib

    if not Path(path).is_file():
        raise FileNotFoundError(f"{path}: no such result file")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # library version warnings: the caller checks the versions it records
            return joblib.load(path)
    except Exception as err:  # pickle raises anything from EOFError to ModuleNotFoundError
        raise corrupt_input(
            path,
            f"not a readable joblib file (truncated, or from another version: "
            f"{type(err).__name__}: {str(err).strip()[:120]})",
        ) from err
