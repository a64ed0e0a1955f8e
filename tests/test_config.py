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


@pytest.mark.parametrize("mutate,needle", [
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
])
def test_bad_values_are_named(cfg, mutate, needle):
    mutate(cfg)
    with pytest.raises(Exception) as err:
        _validate(cfg)
    assert needle in str(err.value)


def test_missing_table_is_named(cfg):
    cfg["musculoskeletal"]["table_path"] = "/nonexistent/moments.csv"
    with pytest.raises(settings.ConfigError, match="table_path"):
        settings.check_config(cfg)
