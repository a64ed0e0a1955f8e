"""Run ledger with MLflow tracking.

One MLflow run per workflow run and patient: params = the patient's config
slice and coded levels, metrics = the headline figures found in ``results/``,
artifacts = the patient's datasets and plots; tags = config hash, git commit,
package versions.  The tracking URI is a config value (default: a local SQLite
store under ``results/tracking``), so a team can point it at its own server.

Compare two runs side by side::

    python -m workflow.common.tracking compare RUN_A RUN_B [--uri sqlite:///results/tracking/mlflow.db]
    python -m workflow.common.tracking list
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np

from workflow.common.provenance import config_sha256, git_commit, open_result, package_versions

__all__ = ["headline_metrics", "rule_times", "flatten", "log_run", "compare_runs", "main", "DEFAULT_URI", "COLLECTORS"]

DEFAULT_URI = "sqlite:///results/tracking/mlflow.db"


def flatten(d: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested mapping -> ``{"a.b.c": value}`` (MLflow params are flat strings)."""
    out: dict[str, Any] = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(flatten(v, key + "."))
        else:
            out[key] = v
    return out


def _scaling_metrics(results: Path, patient: str) -> dict[str, float]:
    p = results / "validation" / "scaling.nc"
    with open_result(p) as ds:
        return {"scaling_max_abs_error": float(ds.attrs["max_abs_error_excluding_paper_inconsistency"])}


def _rsm_metrics(results: Path, patient: str) -> dict[str, float]:
    out: dict[str, float] = {}
    with open_result(results / "musculoskeletal" / "rsm.nc") as ds:
        sel = ds["r2"].where(ds["selected"]).max("form")
        for finger in sorted({str(r).split("_")[0] for r in ds["response"].values}):
            names = [r for r in ds["response"].values if str(r).startswith(finger)]
            out[f"rsm_{finger}_r2_min"] = float(sel.sel(response=names).min())
            out[f"rsm_{finger}_r2_max"] = float(sel.sel(response=names).max())
    return out


def _joint_load_metrics(results: Path, patient: str) -> dict[str, float]:
    out: dict[str, float] = {}
    with open_result(results / "patients" / patient / "joint_loads.nc") as ds:
        for j in ds["joint"].values:
            out[f"active_limit_{j}_nm"] = float(ds["active_limit_nm"].sel(joint=j))
            out[f"passive_max_{j}_nm"] = float(ds["passive_moment_nm"].sel(joint=j).max())
        out["in_design_range"] = float(bool(ds["in_design_range"]))
        for dim, val in zip(ds["dimension"].values, ds["x"].values):
            out[f"x_{dim}"] = float(val)
    return out


def _cascade_metrics(results: Path, patient: str) -> dict[str, float]:
    with open_result(results / "patients" / patient / "cascade_plan.nc") as ds:
        return {"exercises_achieved": float(np.asarray(ds["achieved"].values, bool).sum())}


def _surrogate_metrics(results: Path, patient: str) -> dict[str, float]:
    out: dict[str, float] = {}
    with open_result(results / "actuator" / "surrogate_cv.nc") as ds:
        mean = ds[["r2", "rmse"]].mean("fold")
        for fea in ds["fea"].values:
            for tgt in ds["target"].values:
                for reg in ds["regressor"].values:
                    v = mean.sel(fea=fea, target=tgt, regressor=reg)
                    out[f"cv_{fea}_{tgt}_{reg}_r2"] = float(v["r2"])
    return out


def _fea_check_metrics(results: Path, patient: str) -> dict[str, float]:
    out: dict[str, float] = {}
    with open_result(results / "patients" / patient / "fea_check.nc") as ds:
        out["fea_check_reached"] = float(np.asarray(ds["achieved"].values, bool).sum())
        if "achieved_corrected" in ds:
            out["fea_check_reached_corrected"] = float(np.asarray(ds["achieved_corrected"].values, bool).sum())
        for e in ds["exercise"].values:
            out[f"fea_check_{e}_max_abs_error_deg"] = float(np.abs(ds["angle_error_deg"].sel(exercise=e)).max())
            out[f"fea_check_{e}_wall_s"] = float(ds["wall_time_s"].sel(exercise=e))
        out["fea_check_ndofs"] = float(ds["ndofs"])
    return out


def _fidelity_metrics(results: Path, patient: str) -> dict[str, float]:
    out: dict[str, float] = {}
    with open_result(results / "fidelity" / "fem.nc") as ds:
        for m in ds["model_choice"].values:
            out[f"fidelity_fem_{m}_h_mm"] = float(ds["chosen_h_mm"].sel(model_choice=m))
            case = str(ds["chosen_case"].sel(model_choice=m).values)
            out[f"fidelity_fem_{m}_max_rel_error"] = float(ds["error"].sel(case=case).max())
            out[f"fidelity_fem_{m}_wall_s"] = float(ds["wall_time_s"].sel(case=case))
    return out


#: headline metrics per result file; a file that is absent contributes nothing.
COLLECTORS: tuple[tuple[str, Callable[[Path, str], dict[str, float]]], ...] = (
    ("validation/scaling.nc", _scaling_metrics),
    ("musculoskeletal/rsm.nc", _rsm_metrics),
    ("patients/{patient}/joint_loads.nc", _joint_load_metrics),
    ("patients/{patient}/cascade_plan.nc", _cascade_metrics),
    ("actuator/surrogate_cv.nc", _surrogate_metrics),
    ("patients/{patient}/fea_check.nc", _fea_check_metrics),
    ("fidelity/fem.nc", _fidelity_metrics),
)


def headline_metrics(results: str | Path, patient: str) -> dict[str, float]:
    """Headline figures of one patient's run, from whatever result files exist."""
    results = Path(results)
    out: dict[str, float] = {}
    for rel, fn in COLLECTORS:
        if (results / rel.format(patient=patient)).is_file():
            out.update(fn(results, patient))
    return {k: v for k, v in out.items() if np.isfinite(v)}


def rule_times(bench_dir: str | Path) -> dict[str, float]:
    """Wall seconds per rule (and wildcard instance) from Snakemake's ``benchmark:`` files."""
    out: dict[str, float] = {}
    for f in sorted(Path(bench_dir).glob("**/*.tsv")):
        with f.open() as fh:
            rows = list(csv.DictReader(fh, delimiter="\t"))
        if rows:
            out[f"time_{f.relative_to(bench_dir).with_suffix('').as_posix().replace('/', '.')}_s"] = float(
                rows[-1]["s"]
            )
    return out


def log_run(
    *,
    uri: str,
    experiment: str,
    patient: str,
    params: Mapping[str, Any],
    metrics: Mapping[str, float],
    artifacts: Iterable[str | Path],
    config_slice: Any,
) -> str:
    """Log one run; returns its MLflow run id."""
    import fcntl

    if uri.startswith("sqlite:///"):
        db = Path(uri.removeprefix("sqlite:///"))
        db.parent.mkdir(parents=True, exist_ok=True)
        # Two jobs creating the SQLite schema at once collide; serialise writers.
        with open(db.with_suffix(".lock"), "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            return _log_run(uri, experiment, patient, params, metrics, artifacts, config_slice)
    return _log_run(uri, experiment, patient, params, metrics, artifacts, config_slice)


def _log_run(uri, experiment, patient, params, metrics, artifacts, config_slice) -> str:
    import mlflow

    mlflow.set_tracking_uri(uri)
    if mlflow.get_experiment_by_name(experiment) is None:
        art = Path(uri.removeprefix("sqlite:///")).parent / "artifacts" if uri.startswith("sqlite:///") else None
        mlflow.create_experiment(experiment, artifact_location=art.resolve().as_uri() if art else None)
    mlflow.set_experiment(experiment)
    with mlflow.start_run(run_name=f"{patient}") as run:
        mlflow.set_tags(
            {
                "patient": patient,
                "config_sha256": config_sha256(config_slice),
                "git_commit": git_commit(),
                "package_versions": json.dumps(package_versions(), sort_keys=True),
            }
        )
        flat = {k: str(v)[:500] for k, v in flatten(params).items()}
        mlflow.log_params(flat)
        mlflow.log_metrics(dict(metrics))
        for a in artifacts:
            if Path(a).is_file():
                mlflow.log_artifact(str(a))
        return run.info.run_id


def compare_runs(uri: str, run_a: str, run_b: str):
    """Side-by-side table (pandas DataFrame) of two runs' params, metrics and tags."""
    import mlflow
    import pandas as pd

    client = mlflow.MlflowClient(tracking_uri=uri)
    cols = {}
    for rid in (run_a, run_b):
        r = client.get_run(rid)
        row = {f"param.{k}": v for k, v in r.data.params.items()}
        row.update({f"metric.{k}": v for k, v in r.data.metrics.items()})
        row.update({f"tag.{k}": v for k, v in r.data.tags.items() if not k.startswith("mlflow.")})
        cols[f"{r.info.run_name} ({rid[:8]})"] = row
    df = pd.DataFrame(cols)
    a, b = df.columns
    df["differs"] = df[a].astype(str) != df[b].astype(str)
    return df.sort_values(["differs"], ascending=False)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m workflow.common.tracking", description=__doc__.split("\n\n")[0])
    ap.add_argument("--uri", default=DEFAULT_URI, help="MLflow tracking URI (default: %(default)s)")
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("compare", help="two runs side by side")
    c.add_argument("run_a")
    c.add_argument("run_b")
    c.add_argument("--all", action="store_true", help="show rows that are equal too")
    sub.add_parser("list", help="runs in the ledger, newest first")
    args = ap.parse_args(argv)
    import mlflow

    if args.cmd == "list":
        mlflow.set_tracking_uri(args.uri)
        runs = mlflow.search_runs(search_all_experiments=True)
        keep = [
            c
            for c in ("run_id", "tags.mlflow.runName", "start_time", "tags.git_commit", "tags.config_sha256")
            if c in runs
        ]
        print(runs[keep].to_string(index=False))
        return 0
    df = compare_runs(args.uri, args.run_a, args.run_b)
    if not args.all:
        df = df[df["differs"]]
    print(df.drop(columns="differs").to_string())
    return 0


if __name__ == "__main__":
    sys.exit(main())
