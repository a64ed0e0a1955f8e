"""The authors' settings study: each variant's config changes exactly what its setting names, the profile file is
the study's "all", and the pieces a setting switches on (a pocket floor, linear joint springs, a shifted layout) do
what they say; the study's table reads the corrected outcome of each check."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
import yaml
from _doubles import mean_finger

from workflow import fem, settings
from workflow.authors_study import settings as S
from workflow.authors_study.summary import study_dataset
from workflow.cascade import finger as F
from workflow.cascade import model as C
from workflow.cascade.patient import linear_springs
from workflow.fea_check.outcome import final_outcome


def _leaves(d, prefix=""):
    out = {}
    for k, v in d.items():
        p = f"{prefix}.{k}" if prefix else k
        out.update(_leaves(v, p) if isinstance(v, dict) else {p: v})
    return out


def test_each_variant_changes_exactly_the_keys_its_setting_names(config):
    study = config["authors_study"]
    names = S.variant_names(study)
    assert names[0] == S.BASELINE and names[-1] == S.ALL and len(names) == len(study["settings"]) + 2
    # the baseline is the config with the study's exercises checked, nothing else
    base = S.variant_config(config, S.BASELINE)
    assert S.changed_paths(config, base) == (["fea_check.exercises"] if study["exercises"] else [])
    every = set()
    for name, over in study["settings"].items():
        named = {p for p, v in _leaves(over).items() if _leaves(base).get(p, object()) != v}
        assert named, f"setting {name} changes nothing"
        assert set(S.changed_paths(base, S.variant_config(config, name))) == named
        every |= named
    assert set(S.changed_paths(base, S.variant_config(config, S.ALL))) == every


def test_the_profile_file_is_the_study_all_variant(config):
    profile = yaml.safe_load((settings.REPO_ROOT / "config" / "authors_2d.yaml").read_text())
    assert _leaves(profile) == _leaves(S.variant_overrides(config["authors_study"], S.ALL))


def test_every_variant_is_a_valid_config(config):
    from snakemake.utils import validate

    for name in S.variant_names(config["authors_study"]):
        c = S.variant_config(config, name)
        validate(c, str(settings.SCHEMA_PATH))
        settings.check_config(c)


def test_only_the_unit_settings_rerun_the_unit(config):
    study = config["authors_study"]
    unit = {n for n in S.variant_names(study) if S.changes_unit(S.variant_overrides(study, n))}
    assert unit == {"silicone", "section", "paper", S.ALL}


def test_overlapping_or_reserved_settings_are_refused():
    with pytest.raises(ValueError, match="both set cascade.gravity_m_s2"):
        S.variant_overrides(
            {"settings": {"a": {"cascade": {"gravity_m_s2": 0}}, "b": {"cascade": {"gravity_m_s2": 1}}}}, "a"
        )
    with pytest.raises(ValueError, match="reserved"):
        S.variant_overrides({"settings": {"all": {"cascade": {"gravity_m_s2": 0}}}}, "all")
    with pytest.raises(ValueError, match="no variant 'x'"):
        S.variant_overrides({"settings": {}}, "x")


def test_deep_merge_replaces_leaves_and_leaves_the_base_alone():
    base = {"a": {"b": 1, "c": [1, 2]}, "d": 3}
    out = S.deep_merge(base, {"a": {"c": [5]}})
    assert out == {"a": {"b": 1, "c": [5]}, "d": 3} and base["a"]["c"] == [1, 2]


def test_a_pocket_floor_raises_the_pocket_and_keeps_its_walls_closed():
    g = {"depth": 6.88, "height": 10.0, "ac_th_down": 3.0}
    m = fem.build_unit_mesh(g, h=0.5, dim=2)
    yb = 0.1 + 2.0
    for k in range(3):
        f = m.facets[f"pocket_top{k}"]
        y = m.mesh.p[1, f]
        # floor 3 mm above the block base, roof 2 mm below its top: 2.88 x 5 mm (perimeter 15.76 mm)
        assert y.min() == pytest.approx(yb + 3.0) and y.max() == pytest.approx(yb + 8.0)
        length = np.linalg.norm(np.diff(m.mesh.p[:, f], axis=2)[..., 0], axis=0).sum()
        assert length == pytest.approx(2 * (2.88 + 5.0))
    # no pocket floor is the Table 6 mesh, node for node
    a, b = fem.build_unit_mesh({"ac_th_down": 0.0}, h=1.0), fem.build_unit_mesh(None, h=1.0)
    assert np.array_equal(a.mesh.p, b.mesh.p) and np.array_equal(a.mesh.t, b.mesh.t)
    with pytest.raises(ValueError, match="pocket floor"):
        fem.build_unit_mesh({"ac_th_down": 13.0}, h=1.0)


def test_linear_springs_pass_through_the_passive_moment_at_each_largest_target():
    joints = ["MCP", "PIP", "DIP"]
    loads = xr.Dataset(
        {
            "target_angle_deg": (("exercise", "joint"), [[0.0, 0.0, 0.0], [90.0, 0.0, 0.0], [90.0, 100.0, 80.0]]),
            "passive_moment_nm": (("exercise", "joint"), [[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.05, 0.025, 0.003]]),
        },
        coords={"exercise": ["TGE1", "TGE2", "TGE4"], "joint": joints},
    )
    springs = linear_springs(loads)
    for s, (a, m) in zip(springs, [(90.0, 0.05), (100.0, 0.025), (80.0, 0.003)]):
        assert s.moment_nm(a) == pytest.approx(m) and s.moment_nm(a / 2) == pytest.approx(m / 2)


def test_the_layout_shift_moves_every_unit_and_nothing_else():
    f = mean_finger(springs=[F.JointSpring.linear(1e-3)] * 3)
    dims = {
        "depth": 6.8,
        "gap": 1.0,
        "width": 20.0,
        "height": 15.0,
        "ch_depth": 2.8,
        "ch_width": 14.0,
        "ch_height": 13.0,
        "bot_layer": 2.0,
        "paper_width": 0.2,
    }
    unit = type("U", (), {})()
    a = C.build_cascade(f, unit, actuator_dims_mm=dims)
    b = C.build_cascade(f, unit, actuator_dims_mm=dims, layout_shift_mm=-25.8)
    assert np.allclose(b.unit_ref[:, 0] - a.unit_ref[:, 0], -25.8e-3)
    assert b.base_x_m - a.base_x_m == pytest.approx(-25.8e-3)
    assert a.n_per_group == b.n_per_group


def _check(reached_first, reached_corrected, load):
    ex, joints = ["TGE1", "TGE2"], ["MCP", "PIP", "DIP"]
    return xr.Dataset(
        {
            "angle_deg": (("exercise", "joint"), [[9.0, 1.0, 4.0], [30.0, 11.0, 1.0]]),
            "corrected_angle_deg": (("exercise", "joint"), [[4.0, 0.0, 4.0], [32.0, 11.0, 1.0]]),
            "target_angle_deg": (("exercise", "joint"), [[0.0, 0.0, 0.0], [90.0, 0.0, 0.0]]),
            "achieved": ("exercise", reached_first),
            "achieved_corrected": ("exercise", reached_corrected),
            "converged": ("exercise", [True, load >= 1]),
            "load_factor": ("exercise", [1.0, load]),
            "max_strap_force_n": (("exercise", "strap"), [[1.0, 2.0], [6.0, 3.0]]),
            "max_actuator_moment_nm": (("exercise", "joint"), [[0.01, -0.02, 0.0], [0.1, 0.0, 0.0]]),
            "active_limit_nm": ("joint", [1.0, 0.5, 0.2]),
            "within_limits": ("exercise", [True, True]),
            "reason": ("exercise", np.array(["", "MCP off target"], dtype=object)),
        },
        coords={"exercise": ex, "joint": joints, "strap": ["PIP", "DIP"]},
    )


def test_the_study_table_reads_the_corrected_outcome():
    ds = study_dataset(
        {"baseline": _check([False, False], [True, False], 0.46), "gravity": _check([False, False], [True, True], 1.0)},
        {"baseline": [], "gravity": ["cascade.gravity_m_s2"]},
    )
    assert list(ds["n_reached"].values) == [1, 2]
    assert ds["angle_deg"].sel(variant="baseline", exercise="TGE1").values.tolist() == [4.0, 0.0, 4.0]
    assert float(ds["load_factor"].sel(variant="baseline", exercise="TGE2")) == 0.46
    assert float(ds["max_strap_force_n"].sel(variant="gravity", exercise="TGE2")) == 6.0
    assert float(ds["moment_share_of_limit"].sel(variant="gravity", exercise="TGE1")) == pytest.approx(0.04)
    assert ds["changes"].sel(variant="gravity").item() == "cascade.gravity_m_s2"


def test_the_final_outcome_is_the_first_solve_where_no_correction_ran():
    full = _check([True, False], [False, True], 1.0)
    corrected = final_outcome(full)
    assert corrected.attrs["corrected"] == 1
    assert corrected["reached"].values.tolist() == [False, True]
    assert corrected["angle_deg"].sel(exercise="TGE1").values.tolist() == [4.0, 0.0, 4.0]
    first = final_outcome(full.drop_vars(["corrected_angle_deg", "achieved_corrected"]))
    assert first.attrs["corrected"] == 0
    assert first["reached"].values.tolist() == [True, False]
    assert first["angle_deg"].sel(exercise="TGE1").values.tolist() == [9.0, 1.0, 4.0]
