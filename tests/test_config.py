"""Bad input fails before any job, with a message naming the problem."""

import copy

import pytest
from snakemake.utils import validate

from workflow import settings


def _validate(cfg):
    validate(cfg, str(settings.SCHEMA_PATH))
    settings.check_config(cfg)


@pytest.fixture
def cfg(config):
    c = copy.deepcopy(config)
    c["musculoskeletal"]["backend"] = "table"
    c["musculoskeletal"]["table_path"] = __file__  # any existing file: the check is for existence
    return c


def test_default_config_is_valid(cfg):
    _validate(cfg)


@pytest.mark.parametrize(
    "mutate,needle",
    [
        (lambda c: c.update(desing={}), "desing"),
        (lambda c: c["rsm"].update(alpah=0.1), "alpah"),
        (lambda c: c["rsm"].update(alpha=1.5), "1.5"),
        (lambda c: c["musculoskeletal"].update(backend="matlab"), "matlab"),
        (lambda c: c["patients"].update(p9={"measurements_mm": {"L3PP": -52.0}}), "-52.0"),
        (lambda c: c["patients"].update(p9={"measurements_mm": {"L3XX": 52.0}}), "L3XX"),
        (lambda c: c["patients"].update(p9={"coded": {"depth": 0, "length": 0}}), "breadth"),
        (lambda c: c["exercises"].update(TGE6={"mcp": 120, "pip": 0, "dip": 0}), "120"),
        (lambda c: c["patients"]["mean"].update(model="robot"), "robot"),
        (lambda c: c["cascade"].update(dummy_patient="nobody"), "nobody"),
        (lambda c: c["cascade"].update(dummy_patient="mean"), "model: dummy"),
        (lambda c: c["cascade"].update(validation_patient="nobody"), "validation_patient"),
        (lambda c: c["patients"].update(p9={"measurements_mm": {"L3PP": 0.0}}), "'measurements_mm'"),
        (lambda c: c["patients"].update(p9={"measurements_mm": {"L3PP": float("nan")}}), "L3PP = nan"),
        (lambda c: c["patients"].update(p9={"measurements_mm": {"L3PP": "52"}}), "'52' is not of type 'number'"),
        (lambda c: c["patients"].update(p9={"finger": "F6", "coded": {"depth": 0, "length": 0, "breadth": 0}}), "'F6'"),
        (
            lambda c: c["patients"].update(
                p9={"coded": {"depth": 0, "length": 0, "breadth": 0}, "measurements_mm": {"L3PP": 50.0}}
            ),
            "is valid under each of",
        ),
        (lambda c: c["actuator"]["unit_check"].update(p_top_kpa=[-60.0]), "-60.0"),
        (lambda c: c["actuator"]["mesh"].update(h_2d_mm=0.0), "'h_2d_mm'"),
        (lambda c: c["surrogates"].update(folds=1), "'folds'"),
        (lambda c: c["surrogates"].update(k=0), "['k']"),
        (lambda c: c["patients"].update({"p/1": {"coded": {"depth": 0, "length": 0, "breadth": 0}}}), "'p/1'"),
        (lambda c: c["fea_check"].update(patients=["mean", "nobody"]), "fea_check.patients: 'nobody'"),
        (lambda c: c["fea_check"].update(patients="some"), "'some'"),
        (lambda c: c["actuator"]["geometry"].update(fillet=2.5), "actuator.geometry.fillet = 2.5 mm"),
        (lambda c: c["actuator"]["geometry"].update(fillet=-1.0), "-1.0"),
    ],
)
def test_bad_values_are_named(cfg, mutate, needle):
    mutate(cfg)
    with pytest.raises(Exception) as err:
        _validate(cfg)
    assert needle in str(err.value)


def test_checked_patients_default_to_the_validation_patient_and_the_dummy(cfg):
    assert settings.checked_patients(cfg) == ["mean", "dummy"]
    cfg["fea_check"]["patients"] = "all"
    assert settings.checked_patients(cfg) == sorted(cfg["patients"])
    cfg["fea_check"]["patients"] = ["altered", "altered"]
    assert settings.checked_patients(cfg) == ["altered"]
    cfg["fea_check"]["patients"] = None
    del cfg["cascade"]["dummy_patient"]
    assert settings.checked_patients(cfg) == ["mean"]


def test_missing_table_is_named(cfg):
    cfg["musculoskeletal"]["table_path"] = "/nonexistent/moments.csv"
    with pytest.raises(settings.ConfigError, match="table_path"):
        settings.check_config(cfg)


# --- Safety checks at parse time: pressures, measurement codes, coded levels, the silicone's law ------------
@pytest.mark.parametrize(
    "mutate,needles",
    [
        # more pressure than the silicone bears (Fig. 11: 300 kPa the largest considered)
        (
            lambda c: c["cascade"].update(p_max_kpa=3000.0),
            ["cascade.p_max_kpa = 3000", "actuator.material.p_limit_kpa = 300"],
        ),
        (lambda c: c["sweep"]["3d"].update(p_max_kpa=400.0), ["sweep.3d.p_max_kpa = 400", "p_limit_kpa = 300"]),
        (lambda c: c["stability"]["rays"].update(p_max_kpa=350.0), ["stability.rays.p_max_kpa = 350", "300"]),
        (
            lambda c: c["cascade"]["calibration"]["fit_pressures_2d_kpa"].append([400, 0, 0, 0, 0, 0, 0, 0]),
            ["cascade.calibration.fit_pressures_2d_kpa[7] = 400", "300"],
        ),
        (lambda c: c["cascade"]["calibration"].update(patient="meen"), ["cascade.calibration.patient = 'meen'"]),
        (lambda c: c["cascade"]["calibration"].update(gain_bounds=[1.5, 0.1]), ["gain_bounds = [1.5, 0.1]"]),
        # more pressure than the plans' surrogate was sampled on
        (lambda c: c["sweep"]["3d"].update(p_max_kpa=200.0), ["cascade.p_max_kpa = 300", "sweep.3d.p_max_kpa = 200"]),
        # a middle-finger code on the index finger
        (lambda c: c["patients"].update(p1={"finger": "F2", "measurements_mm": {"L3PP": 50.0}}), ["L3PP", "F2"]),
        (lambda c: c["patients"].update(p1={"finger": "F3", "measurements_mm": {"L2PP": 50.0}}), ["L2PP", "F3"]),
        # implausible coded levels: given, or from a measurement in the wrong unit (cm)
        (
            lambda c: c["patients"].update(p1={"coded": {"depth": 5.0, "length": 0.0, "breadth": 0.0}}),
            ["depth 5", "coded_bound"],
        ),
        (lambda c: c["patients"].update(p1={"measurements_mm": {"L3PP": 5.06}}), ["length -12", "coded_bound"]),
        # the Mooney-Rivlin law unstable at rest, or within the stretches an FE model meets
        # (with Table 5's c01 and c20, as in the config)
        (
            lambda c: c["actuator"]["material"].update(c10_mpa=-0.26, c01_mpa=0.09754981, c20_mpa=0.05750069),
            ["c10_mpa = -0.26", "mu0", "<= 0"],
        ),
        (
            lambda c: c["actuator"]["material"].update(c10_mpa=0.26, c01_mpa=0.1, c20_mpa=-0.01),
            ["Drucker", "equibiaxial"],
        ),
    ],
)
def test_unsafe_values_stop_before_any_job(cfg, mutate, needles):
    mutate(cfg)
    with pytest.raises(settings.ConfigError) as err:
        _validate(cfg)
    for needle in needles:
        assert needle in str(err.value)


@pytest.mark.parametrize("table5", [False, True])
def test_default_and_table5_constants_pass_with_no_warning(cfg, table5):
    m = cfg["actuator"]["material"]
    assert m["p_limit_kpa"] == 300.0 and "Fig. 11" in m["p_limit_source"]
    if table5:  # Table 5 read correctly: C10 = 260,567.62, C01 = 97,549.81, C20 = 57,500.69 Pa
        m.update(c10_mpa=0.26056762, c01_mpa=0.09754981, c20_mpa=0.05750069)
    validate(cfg, str(settings.SCHEMA_PATH))
    assert settings.check_config(cfg) == []


def test_marginal_constants_and_a_patient_outside_the_design_region_warn(cfg):
    # c20 < 0 softens the law: unstable in equibiaxial compression below stretch 0.45, outside 0.5-2
    cfg["actuator"]["material"].update(c10_mpa=0.26, c01_mpa=0.1, c20_mpa=-0.003)
    cfg["patients"]["p1"] = {"coded": {"depth": 1.5, "length": 0.0, "breadth": 0.0}}
    validate(cfg, str(settings.SCHEMA_PATH))
    warnings = settings.check_config(cfg)
    assert len(warnings) == 2
    assert "patients.p1.coded" in warnings[0] and "outside the design region" in warnings[0]
    assert "equibiaxial mode unstable at stretch 0.3-0.451" in warnings[1]
