"""Shared fixtures: paths, the authors' data (skipped cleanly where absent), one seed."""

from __future__ import annotations

from pathlib import Path

import pytest

from workflow import settings

REPO = settings.REPO_ROOT
SHARED = REPO.parent / "shared"
AUTHORS_MOMENTS = SHARED / "data" / "opensim_ccd_joint_moments.csv"


@pytest.fixture(scope="session")
def repo() -> Path:
    return REPO


@pytest.fixture(scope="session")
def config() -> dict:
    """The default config, validated, with schema defaults filled (no file checks)."""
    from snakemake.utils import validate

    import yaml

    cfg = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    validate(cfg, str(settings.SCHEMA_PATH))
    return cfg


@pytest.fixture(scope="session")
def authors_moments() -> Path:
    if not AUTHORS_MOMENTS.is_file():
        pytest.skip(f"the authors' OpenSim export is absent ({AUTHORS_MOMENTS}); tests that compare with it are skipped")
    return AUTHORS_MOMENTS


@pytest.fixture
def seed() -> int:
    """One seed for everything random in a test (DOE, CV splits, surrogates)."""
    return 20240917
