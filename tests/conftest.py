"""Shared fixtures: paths, the default config, the authors' data (carried in resources/), the seeds."""

from __future__ import annotations

from pathlib import Path

import pytest

from workflow import settings

REPO = settings.REPO_ROOT
#: The authors' OpenSim export at the CCD runs (carried into resources/ with its citation).
AUTHORS_MOMENTS = REPO / "resources" / "opensim_ccd_joint_moments.csv"


@pytest.fixture(scope="session")
def repo() -> Path:
    return REPO


@pytest.fixture(scope="session")
def config() -> dict:
    """The default config, validated, with schema defaults filled (no file checks)."""
    import yaml
    from snakemake.utils import validate

    cfg = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    validate(cfg, str(settings.SCHEMA_PATH))
    return cfg


@pytest.fixture(scope="session")
def authors_moments() -> Path:
    assert AUTHORS_MOMENTS.is_file(), f"the authors' OpenSim export is missing from the repository: {AUTHORS_MOMENTS}"
    return AUTHORS_MOMENTS


#: A small range of seeds: a test that passes for one seed only is not a result.
SEEDS = (20240917, 7, 42)


@pytest.fixture(params=SEEDS, ids=lambda s: f"seed{s}")
def seed(request) -> int:
    """A seed for everything random in a test (DOE, CV splits, surrogates), over `SEEDS`."""
    return request.param
