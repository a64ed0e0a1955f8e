"""The layout design: the candidates honour their bounds, the exhaustive search returns the known optimum of a small
synthetic problem, and the choice among the checked layouts follows the FEA, not the chain."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from workflow import settings
from workflow.common.constants import GROUPS
from workflow.layout.choice import CheckedLayout, choose_layout
from workflow.layout.entry_choice import write_layout_choice
from workflow.layout.search import LayoutOutcome, candidate_layouts, overhang_mm, rank_outcomes, search_layouts
from workflow.layout.units import chosen_units, top_units

BOUNDS = {"CMC": [4, 6], "MCP": [5, 7], "PIP": [3, 5], "DIP": [3, 5]}


def test_candidates_honour_the_group_length_and_mass_bounds():
    every = candidate_layouts(BOUNDS, unit_length_mm=7.8, unit_mass_g=4.6)
    assert len(every) == 3**4
    short = candidate_layouts(BOUNDS, unit_length_mm=7.8, unit_mass_g=4.6, max_length_mm=7.8 * 17)
    assert short and all(sum(c) <= 17 for c in short) and len(short) < len(every)
    light = candidate_layouts(BOUNDS, unit_length_mm=7.8, unit_mass_g=4.6, max_mass_g=4.6 * 16)
    assert len(light) == 5 and all(sum(c) <= 16 for c in light)  # the 15-unit minimum and its four +1 neighbours
    with pytest.raises(ValueError, match="more than max_candidates"):
        candidate_layouts(BOUNDS, unit_length_mm=7.8, unit_mass_g=4.6, max_candidates=10)
    with pytest.raises(ValueError, match="no layout within"):
        candidate_layouts(BOUNDS, unit_length_mm=7.8, unit_mass_g=4.6, max_length_mm=10.0)
    with pytest.raises(ValueError, match="PIP = \\[5, 3\\]"):
        candidate_layouts({**BOUNDS, "PIP": [5, 3]}, unit_length_mm=7.8, unit_mass_g=4.6)


def test_candidates_honour_the_overhang_past_the_fingertip():
    """The CMC group ends at the MCP joint, so MCP + PIP + DIP units set the overhang: with a tip 100 mm past the MCP
    joint and 10 mm units, at most 10 mm of overhang leaves the layouts of at most 11 distal units."""
    every = candidate_layouts(BOUNDS, unit_length_mm=10.0, unit_mass_g=4.6)
    kept = candidate_layouts(BOUNDS, unit_length_mm=10.0, unit_mass_g=4.6, tip_mm=100.0, max_overhang_mm=10.0)
    assert kept == [c for c in every if sum(c[1:]) <= 11]  # the CMC count does not matter
    assert len(kept) == 3 * 1  # MCP 5, PIP 3, DIP 3 with any of the three CMC counts
    assert overhang_mm((4, 5, 3, 3), unit_length_mm=10.0, tip_mm=100.0) == pytest.approx(10.0)
    # the whole actuator moved 20 mm proximally: the overhang falls by 20 mm, two more units per layout fit
    shifted = candidate_layouts(
        BOUNDS, unit_length_mm=10.0, unit_mass_g=4.6, tip_mm=100.0, max_overhang_mm=10.0, layout_shift_mm=-20.0
    )
    assert shifted == [c for c in every if sum(c[1:]) <= 13]
    with pytest.raises(ValueError, match="no layout within .* and -50 mm past the fingertip"):
        candidate_layouts(BOUNDS, unit_length_mm=10.0, unit_mass_g=4.6, tip_mm=100.0, max_overhang_mm=-50.0)


def test_the_search_returns_the_known_optimum_of_a_synthetic_problem():
    # an exercise is reached when its span has enough units; more units need less pressure, but cost mass:
    # the optimum reaches all three with the fewest units that do, at the least pressure among those
    need = [(10, 0, 0), (10, 4, 0), (11, 4, 4)]  # (CMC+MCP, PIP, DIP) units each exercise needs

    def evaluate(layout):
        spans = (layout[0] + layout[1], layout[2], layout[3])
        reached = tuple(all(s >= n for s, n in zip(spans, req)) for req in need)
        pressure = 300.0 - 5.0 * sum(layout) + 0.1 * layout[0]  # CMC units are the dearest
        return LayoutOutcome(layout, reached, pressure)

    cands = candidate_layouts(BOUNDS, unit_length_mm=7.8, unit_mass_g=4.6)
    seen = []
    outcomes, order = search_layouts(cands, evaluate, progress=lambda i, n: seen.append((i, n)))
    assert seen[-1] == (len(cands), len(cands))
    best = outcomes[order[0]]
    # every exercise needs 11 MCP-span, 4 PIP and 4 DIP units: the least pressure is the most units in all
    assert best.n_reached == 3 and best.layout == (6, 7, 5, 5)
    # the brute force agrees
    full = [o for o in outcomes if o.n_reached == 3]
    assert best.mean_pressure_kpa == min(o.mean_pressure_kpa for o in full)
    # ties on reached and pressure go to the fewest units
    a, b = LayoutOutcome((4, 5, 3, 3), (True,), 100.0), LayoutOutcome((5, 5, 3, 3), (True,), 100.0)
    assert rank_outcomes([b, a]) == [1, 0]


def _search():
    units = np.array([[6, 7, 5, 5], [5, 6, 4, 4], [4, 5, 3, 3]], dtype="i4")
    return xr.Dataset(
        {
            "units": (("candidate", "group"), units),
            "reached": (("candidate", "exercise"), np.array([[True, True], [True, True], [True, False]])),
            "n_reached": ("candidate", np.array([2, 2, 1])),
            "mean_pressure_kpa": ("candidate", np.array([150.0, 180.0, 200.0])),
            "length_mm": ("candidate", units.sum(axis=1) * 7.8),
            "mass_g": ("candidate", units.sum(axis=1) * 4.6),
            "rank": ("candidate", np.array([1, 2, 0], dtype="i4")),  # the candidates' order is not the ranks'
        },
        coords={"candidate": np.arange(3), "group": list(GROUPS), "exercise": ["TGE1", "TGE2"]},
        attrs={"patient": "p", "chain": "double"},
    )


def _check(reached):
    return xr.Dataset(
        {"achieved_corrected": ("exercise", reached), "corrected_angle_deg": (("exercise", "joint"), np.zeros((2, 3)))},
        coords={"exercise": ["TGE1", "TGE2"], "joint": ["MCP", "PIP", "DIP"]},
    )


def test_the_choice_follows_the_fea_not_the_chain(tmp_path):
    search = tmp_path / "search.nc"
    _search().to_netcdf(search)
    checks = []
    for k, r in enumerate([[False, False], [True, False], [True, False]]):
        checks.append(tmp_path / f"c{k}.nc")
        _check(r).to_netcdf(checks[-1])
    ds = write_layout_choice(search, checks, out_nc=tmp_path / "layout.nc", out_png=tmp_path / "l.png", config_slice={})
    # rank 0 (candidate 2) is best on the chain but the FEA reaches nothing; ranks 1 and 2 (candidates 0 and 1)
    # reach TGE1: the cheaper, rank 1 = candidate 0, wins
    assert chosen_units(ds) == {"CMC": 6, "MCP": 7, "PIP": 5, "DIP": 5}
    assert "rank 1" in ds.attrs["why"] and ds["fea_reached"].sum().item() == 2
    assert ds["checked_units"].values[0].tolist() == [4, 5, 3, 3]  # checked in rank order
    assert top_units(_search(), 2) == {"CMC": 5, "MCP": 6, "PIP": 4, "DIP": 4}
    with pytest.raises(ValueError, match="none of rank 3"):
        top_units(_search(), 3)
    assert (tmp_path / "l.png").stat().st_size > 0


def _default_plan(units, achieved, pressure_kpa):
    return xr.Dataset(
        {
            "units_per_group": ("group", np.array(units, dtype="i4")),
            "achieved": ("exercise", np.array(achieved)),
            "pressure_kpa": (("exercise", "group", "chamber"), np.full((2, 4, 2), float(pressure_kpa))),
        },
        coords={"exercise": ["TGE1", "TGE2"], "group": list(GROUPS), "chamber": ["top", "bottom"]},
    )


def _choice_with_default(tmp_path, default_units, default_fea, default_kpa, top_fea=([False, False],) * 3):
    search = tmp_path / "search.nc"
    _search().to_netcdf(search)
    checks = []
    for k, r in enumerate(top_fea):
        checks.append(tmp_path / f"c{k}.nc")
        _check(list(r)).to_netcdf(checks[-1])
    _default_plan(default_units, [True, False], default_kpa).to_netcdf(tmp_path / "dp.nc")
    _check(default_fea).to_netcdf(tmp_path / "dc.nc")
    return write_layout_choice(
        search,
        checks,
        out_nc=tmp_path / "layout.nc",
        out_png=tmp_path / "l.png",
        config_slice={},
        default_plan_nc=tmp_path / "dp.nc",
        default_check_nc=tmp_path / "dc.nc",
    )


def test_the_default_layout_competes_on_the_fea_check(tmp_path):
    # the chain's best three reach nothing in the FEA; the length rule's 5/6/4/4 (candidate 1, rank 2) reaches TGE1:
    # kept, although the chain ranks it last of the three and plans it at a higher pressure
    ds = _choice_with_default(tmp_path, (5, 6, 4, 4), [True, False], 180.0)
    assert chosen_units(ds) == {"CMC": 5, "MCP": 6, "PIP": 4, "DIP": 4}
    assert ds.attrs["chosen"] == "default" and ds["checked_label"].values.tolist()[-1] == "default"
    assert ds["checked_chain_rank"].values.tolist() == [0, 1, 2, 2]
    assert ds["checked_mean_pressure_kpa"].values[-1] == pytest.approx(180.0)
    # a default outside the candidates takes the last chain rank; when it reaches as many as a cheaper checked
    # layout, that one wins and the reason names the default's outcome
    ds = _choice_with_default(
        tmp_path, (8, 8, 6, 6), [True, False], 170.0, top_fea=([False, False], [True, False], [False, False])
    )
    assert ds["checked_chain_rank"].values[-1] == 3
    assert chosen_units(ds) == {"CMC": 6, "MCP": 7, "PIP": 5, "DIP": 5}  # rank 1 at 150 kPa beats 170 kPa
    assert "the default 8/8/6/6 (the plan without the layout design) reaches 1 at 170.0 kPa" in ds.attrs["why"]
    # the same outcome at a lower pressure than every checked layout: the default wins the tie-break on pressure
    ds = _choice_with_default(
        tmp_path, (8, 8, 6, 6), [True, False], 100.0, top_fea=([False, False], [True, False], [False, False])
    )
    assert ds.attrs["chosen"] == "default" and "the default layout, outside the searched bounds" in ds.attrs["why"]
    with pytest.raises(ValueError, match="needs both its plan and its FEA check"):
        write_layout_choice(
            tmp_path / "search.nc",
            [],
            out_nc=tmp_path / "x.nc",
            out_png=tmp_path / "x.png",
            config_slice={},
            default_plan_nc=tmp_path / "dp.nc",
        )


def test_choose_layout_orders_fea_then_pressure_then_chain_rank():
    def row(label, n_fea, kpa, rank):
        fea = np.arange(3) < n_fea
        return CheckedLayout(label, (4, 5, 3, 3), fea, fea, kpa, rank)

    rows = [row("rank 0", 1, 150.0, 0), row("rank 1", 2, 190.0, 1), row("rank 2", 2, 170.0, 2)]
    assert choose_layout(rows) == 2  # two exercises, the cheaper
    rows.append(row("default", 2, 170.0, 1))
    assert choose_layout(rows) == 3  # same FEA and pressure: the better chain rank
    with pytest.raises(ValueError, match="no FEA-checked layout"):
        choose_layout([])


def test_layout_config_errors_name_the_key(config):
    import copy

    bad = copy.deepcopy(config)
    bad["layout"]["patients"] = ["nobody"]
    with pytest.raises(settings.ConfigError, match="layout.patients: 'nobody'"):
        settings.check_config(bad)
    bad = copy.deepcopy(config)
    bad["layout"]["confirm_top"] = 400
    with pytest.raises(settings.ConfigError, match="layout.confirm_top = 400: the bounds hold only"):
        settings.check_config(bad)
    bad = copy.deepcopy(config)
    bad["layout"].update(use=True, calibrated=True)
    bad["cascade"]["calibration"]["use"] = False
    with pytest.raises(settings.ConfigError, match="another chain than the one the layouts were chosen on"):
        settings.check_config(bad)
    bad = copy.deepcopy(config)
    bad["layout"]["bounds"]["CMC"] = [1, 30]
    with pytest.raises(settings.ConfigError, match="layout.bounds: .* candidates, more than max_candidates"):
        settings.check_config(bad)
    # the overhang past each patient's own fingertip (the sum of its phalanx lengths) is checked before any job
    bad = copy.deepcopy(config)
    bad["layout"]["max_overhang_mm"] = -50.0
    with pytest.raises(settings.ConfigError, match=r"-50 mm past the fingertip .*\(patient mean\)"):
        settings.check_config(bad)
    # at most 0 mm past the tip: 50 of the mean finger's 270 layouts (26 mm) remain
    bad["layout"]["max_overhang_mm"] = 0.0
    bad["layout"]["confirm_top"] = 200
    with pytest.raises(
        settings.ConfigError, match="confirm_top = 200: the bounds hold only 50 layouts for patient mean"
    ):
        settings.check_config(bad)


@pytest.mark.parametrize(
    "patient",
    [
        {"coded": {"depth": 0.0, "length": 0.5, "breadth": 0.5}},
        {"measurements_mm": {"L3PP": 55.0, "L3MP": 31.0, "D3PP": 18.0}},  # L3DP from the length level
    ],
)
def test_the_config_check_measures_the_overhang_from_the_fingertip_the_finger_model_builds(config, patient):
    from tests._doubles import linear_springs
    from workflow.cascade import finger as F
    from workflow.musculoskeletal.patient_loads import patient_levels

    anth = config["anthropometry"]
    measures, sd = anth["measures"], float(anth.get("coded_unit_sd", 1.0))
    dims = F.patient_dimensions_mm(measures, patient_levels(patient, measures, sd), sd, patient.get("measurements_mm"))
    fing = F.build_finger(dims, linear_springs(), config["cascade"]["densities"])
    assert settings._fingertip_mm(patient, anth) == pytest.approx(fing.tip_x_m * 1e3, abs=1e-9)
