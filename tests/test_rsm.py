import numpy as np
import pytest

from workflow.doe import ccd as doe
from workflow.musculoskeletal import moments as msm
from workflow.musculoskeletal import patient_loads, rsm, table_backend


@pytest.fixture(scope="module")
def design():
    return doe.ccd_design()


def _quad(x, b):
    d, l, br = x["depth"].to_numpy(), x["length"].to_numpy(), x["breadth"].to_numpy()
    return (
        b[0]
        + b[1] * d
        + b[2] * l
        + b[3] * br
        + b[4] * d**2
        + b[5] * l**2
        + b[6] * br**2
        + b[7] * d * l
        + b[8] * d * br
        + b[9] * l * br
    )


def test_quadratic_fit_recovers_known_coefficients(design, seed):
    rng = np.random.default_rng(seed)
    b = rng.normal(size=10)
    fits = rsm.fit_all(design, {"F3_P_MCP_90": _quad(design, b)})
    ds = rsm.rsm_dataset(fits)
    coef = ds["coef"].sel(response="F3_P_MCP_90", form="quadratic")
    expected = dict(zip(rsm.TERMS[:10], b))
    for term, val in expected.items():
        assert float(coef.sel(term=term)) == pytest.approx(val, abs=1e-8)
    assert float(ds["r2"].sel(response="F3_P_MCP_90", form="quadratic")) == pytest.approx(1.0)
    assert np.isnan(float(coef.sel(term="depth:length:breadth")))


def test_selection_prefers_linear_for_linear_data_with_noise(design, seed):
    rng = np.random.default_rng(seed)
    y = 1 + 0.5 * design["length"].to_numpy() + 0.01 * rng.normal(size=15)
    ds = rsm.rsm_dataset(rsm.fit_all(design, {"F3_P_PIP_90": y}))
    assert ds["selected"].sel(response="F3_P_PIP_90", form="linear")
    assert bool(ds["significant"].sel(response="F3_P_PIP_90"))
    # the linear length term is significant, the breadth term is not
    tp = ds["term_p_value"].sel(response="F3_P_PIP_90", form="linear")
    assert float(tp.sel(term="length")) < 1e-6 < 0.05 < float(tp.sel(term="breadth"))


def test_prediction_interval_contains_the_mean_and_widens_outside(design, seed):
    rng = np.random.default_rng(seed)
    y = 1 + design["depth"].to_numpy() + 0.05 * rng.normal(size=15)
    res = rsm.fit_response(design, y, "linear")
    m, lo, hi = rsm.predict(res, {"depth": 0, "length": 0, "breadth": 0})
    m2, lo2, hi2 = rsm.predict(res, {"depth": 3, "length": 0, "breadth": 0})
    assert lo < m < hi and (hi2 - lo2) > (hi - lo)


def test_authors_export_fits(authors_moments, design, config):
    m = table_backend.moments_from_export(table_backend.read_export(authors_moments), design)
    resp = msm.responses_from_moments(m, config["exercises"])
    assert len(resp) == 28  # 7 responses x 4 fingers
    ds = rsm.rsm_dataset(rsm.fit_all(design, resp))
    q = ds["r2"].sel(form="quadratic")
    assert float(q.min()) > 0.8  # the paper: 0.8344..0.9998
    # breadth has almost no effect (paper, section 2.2): its linear term is the smallest for F3 passive MCP
    c = ds["coef"].sel(response="F3_P_MCP_90", form="linear")
    assert abs(float(c.sel(term="breadth"))) < 0.1 * abs(float(c.sel(term="length")))


def test_patient_loads_zero_at_zero_targets_and_flags_outside(authors_moments, design, config):
    m = table_backend.moments_from_export(table_backend.read_export(authors_moments), design)
    r = rsm.rsm_dataset(rsm.fit_all(design, msm.responses_from_moments(m, config["exercises"])))
    anth = config["anthropometry"]["measures"]
    mean = patient_loads.joint_loads(
        {"coded": {"depth": 0, "length": 0, "breadth": 0}}, m, r, design, config["exercises"], anth
    )
    assert float(mean["passive_moment_nm"].sel(exercise="TGE1").sum()) == 0.0
    assert float(mean["passive_moment_nm"].sel(exercise="TGE2", joint="MCP")) > 0
    assert bool(mean["in_design_range"])
    # active safety limit exceeds the passive moment at the same angle
    assert float(mean["active_limit_nm"].sel(joint="MCP")) > float(
        mean["passive_moment_nm"].sel(exercise="TGE2", joint="MCP")
    )
    lo, hi = mean["passive_moment_lo_nm"], mean["passive_moment_hi_nm"]
    assert bool(((lo <= mean["passive_moment_nm"]) & (mean["passive_moment_nm"] <= hi)).all())
    big = patient_loads.joint_loads({"measurements_mm": {"L3PP": 60.0}}, m, r, design, config["exercises"], anth)
    assert not bool(big["in_design_range"])
    # a longer finger needs a larger passive MCP moment (the authors' data: length is the main effect)
    assert float(big["passive_moment_nm"].sel(exercise="TGE2", joint="MCP")) > float(
        mean["passive_moment_nm"].sel(exercise="TGE2", joint="MCP")
    )


def test_response_names_roundtrip():
    assert msm.parse_response("F3_P_MCP_90") == ("F3", 0.01, "MCP", 90.0)
    assert msm.response_name("F3", 1.0, "PIP", 100.0) == "F3_A_PIP_100"
    with pytest.raises(ValueError):
        msm.parse_response("F3_X_MCP_90")
