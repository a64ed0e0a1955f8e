"""Report tables: datasets -> tables -> standalone HTML pages, on small synthetic datasets."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from workflow.reporting import entry
from workflow.reporting import tables as T

PRESSURES = ["P_CMC_T", "P_CMC_B", "P_MCP_T", "P_MCP_B", "P_PIP_T", "P_PIP_B", "P_DIP_T", "P_DIP_B"]


def _cascade_validation(ours_per_table: bool) -> xr.Dataset:
    ex = ["TGE1", "TGE2"]
    ref = np.arange(2 * 2 * 8, dtype=float).reshape(2, 2, 8)
    ours = np.full((2, 2, 8), 5.0) if ours_per_table else np.full((2, 8), 5.0)
    dims = ("table", "exercise", "pressure") if ours_per_table else ("exercise", "pressure")
    return xr.Dataset(
        {
            "ours": (dims, ours),
            "reference": (("table", "exercise", "pressure"), ref),
            "abs_error": (("table", "exercise", "pressure"), np.abs(ref - 5.0)),
            "ours_achieved": ("exercise", [True, False]),
            "paper_reached": (("paper_set", "exercise"), [[True, True], [True, False]]),
            "reached_agreement": ("paper_set", [0.5, 1.0]),
        },
        coords={
            "table": ["table08", "table10"],
            "exercise": ex,
            "pressure": PRESSURES,
            "paper_set": ["planned_3d", "dummy"],
        },
    )


@pytest.mark.parametrize("per_table", [False, True])
def test_cascade_validation_table_with_and_without_a_plan_per_table(per_table):
    df = T.cascade_validation_table(_cascade_validation(per_table))
    assert df.shape == (16, 6)
    assert df.loc[("TGE2", "P_MCP_T"), "table10 (kPa)"] == pytest.approx(26.0)
    assert df.loc[("TGE1", "P_CMC_T"), "ours for table08 (kPa)"] == pytest.approx(5.0)


def test_reached_table_lists_ours_beside_each_paper_set():
    df = T.reached_table(_cascade_validation(False))
    assert df.loc["TGE2"].tolist() == ["no", "yes", "no"]
    assert df.loc["agreement", "dummy"] == "100%"


def test_surrogate_cv_table_means_over_folds_and_marks_the_choice():
    rng = np.random.default_rng(0)
    shape = (1, 2, 2, 3)
    ds = xr.Dataset(
        {k: (("fea", "regressor", "target", "fold"), rng.random(shape)) for k in ("r2", "mae", "rmse")},
        coords={"fea": ["2d"], "regressor": ["knn", "rbf"], "target": ["angle", "moment"], "fold": [0, 1, 2]},
    )
    ds["score"] = (("fea", "regressor"), [[0.5, 0.1]])
    ds["selected"] = (("fea", "regressor"), [[False, True]])
    df = T.surrogate_cv_table(ds)
    assert df.loc[("2D", "rbf"), "chosen"] == "yes" and df.loc[("2D", "knn"), "chosen"] == ""
    assert df.loc[("2D", "knn"), "angle R2"] == pytest.approx(
        float(ds["r2"].sel(regressor="knn", target="angle").mean())
    )


def test_write_table_writes_a_standalone_page_with_notes(tmp_path):
    ds = _cascade_validation(True)
    ds.attrs["patient"] = "mean"
    ds.to_netcdf(tmp_path / "cascade.nc")
    out = entry.write_table("cascade_validation", tmp_path / "cascade.nc", tmp_path / "t.html")
    text = out.read_text()
    assert text.startswith("<!DOCTYPE html>") and text.rstrip().endswith("</html>")
    assert "patient: mean" in text and text.count("<table") == 2
