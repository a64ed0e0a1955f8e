"""Physiology checks of the generated OpenSim finger model.

Each test asserts something a wrong model would fail: a flexor with an
extension moment arm, a passive curve that falls with flexion, scaling that
ignores depth, a sign convention flipped.  Middle finger (F3) only, to keep the
suite fast; the four-finger model is exercised by the workflow run.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import opensim  # a hard dependency: a broken install fails here, it does not skip
import pandas as pd
import pytest
import xarray as xr

from workflow.musculoskeletal import entry, entry_opensim
from workflow.musculoskeletal import opensim_backend as ob  # noqa: E402
from workflow.musculoskeletal import opensim_model as om  # noqa: E402
from workflow.musculoskeletal import validation as val  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
PARAMS_PATH = REPO / "config" / "finger_muscles.yaml"
TABLE = REPO / "resources" / "table03_04_ccd_scaling.csv"
FLEXORS = ("FDS", "FDP")


@pytest.fixture(scope="module")
def params() -> dict:
    return om.load_parameters(PARAMS_PATH)


@pytest.fixture(scope="module")
def table() -> pd.DataFrame:
    return pd.read_csv(TABLE).set_index("marker")


def factors(table: pd.DataFrame, marker: str) -> dict:
    return {b: tuple(float(table.loc[marker, f"{b}_{a}"]) for a in "XYZ") for b in om.BODIES}


@pytest.fixture(scope="module")
def original(params, table) -> xr.Dataset:
    """F3 scaled to the CCD centre (the mean finger), full 5-degree grid."""
    ref = factors(table, "Original")
    return ob.sample_finger(params, ref, fingers=("F3",), reference_scale=ref).sel(finger="F3")


def test_model_structure_and_osim_roundtrip(params, tmp_path):
    path = om.write_model(params, tmp_path / "finger.osim", ("F3",))
    model = opensim.Model(str(path))
    model.initSystem()
    bodies = {model.getBodySet().get(i).getName() for i in range(model.getBodySet().getSize())}
    assert bodies == {f"F3_{b}" for b in om.BODIES}
    for joint, (lo, hi) in om.JOINT_RANGE_DEG.items():
        c = model.getCoordinateSet().get(om.joint_coordinate_name("F3", joint))
        assert math.degrees(c.getRangeMin()) == pytest.approx(lo)
        assert math.degrees(c.getRangeMax()) == pytest.approx(hi)
    muscles = model.getMuscles()
    names = {muscles.get(i).getName() for i in range(muscles.getSize())}
    assert names == {"F3_FDS", "F3_FDP", "F3_EDC", "F3_LU"}
    for i in range(muscles.getSize()):
        assert muscles.get(i).getConcreteClassName() == "Millard2012EquilibriumMuscle"
    # Segment mass from its dimensions: an elliptic cylinder of the PP's size and density.
    pp = params["fingers"]["F3"]["segments_mm"]["PP"]
    expect = params["density_kg_m3"]["PP"] * math.pi / 4 * pp["length"] * pp["breadth"] * pp["depth"] * 1e-9
    assert model.getBodySet().get("F3_PP").getMass() == pytest.approx(expect, rel=1e-9)


def test_flexors_flex_extensors_extend(original, params):
    arms = original["moment_arm_mm"]
    for joint in om.JOINTS:
        lo, hi = om.JOINT_RANGE_DEG[joint]
        a = arms.sel(joint=joint, angle_deg=slice(lo, hi))
        for m in FLEXORS:
            if joint in params["fingers"]["F3"]["muscles"][m]["moment_arms_mm"]:
                assert (a.sel(muscle=m) > 1.0).all(), f"{m} must flex {joint}"
        assert (a.sel(muscle="EDC") < -1.0).all(), f"EDC must extend {joint}"
    assert (arms.sel(muscle="FDS", joint="DIP").dropna("angle_deg") == 0).all()  # FDS inserts on the MP
    # The lumbrical flexes the MCP and extends the IP joints (through the lateral bands).
    assert (arms.sel(muscle="LU", joint="MCP").dropna("angle_deg") > 0).all()
    for joint in ("PIP", "DIP"):
        assert (arms.sel(muscle="LU", joint=joint).dropna("angle_deg") < 0).all()


def test_moment_arms_are_the_published_ones_at_the_mean_finger(original, params):
    """Tendon excursion of OpenSim's path = the configured (An et al.) arm at every angle."""
    for m, mp in params["fingers"]["F3"]["muscles"].items():
        for joint, arm_mm in mp["moment_arms_mm"].items():
            a = original["moment_arm_mm"].sel(muscle=m, joint=joint).dropna("angle_deg")
            np.testing.assert_allclose(a, arm_mm, atol=2e-3 * abs(arm_mm))
    # OpenSim's own computeMomentArm agrees in sign (it halves the moving-point term; see module doc).
    ours, theirs = original["moment_arm_mm"], original["opensim_moment_arm_mm"]
    ok = np.isfinite(ours) & (np.abs(ours) > 0)
    assert (np.sign(ours.where(ok)) == np.sign(theirs.where(ok))).sum() == ok.sum()


def test_passive_rises_with_flexion_and_stays_below_active(original):
    passive = original["moment_nm"].sel(activation=0.01)
    active = original["moment_nm"].sel(activation=1.0)
    assert (original["status"].where(np.isfinite(original["moment_nm"])).fillna(0) == 0).all()
    for joint in om.JOINTS:
        lo, hi = om.JOINT_RANGE_DEG[joint]
        p = passive.sel(joint=joint, angle_deg=slice(0, hi)).values
        # Holding a more flexed joint takes more flexion moment: antagonists stretch, agonists slacken.
        assert np.all(np.diff(p) > -1e-9), f"{joint}: passive moment must not fall with flexion"
        assert p[-1] - p[0] > 1e-3
        a = active.sel(joint=joint, angle_deg=slice(lo, hi)).values
        pp = passive.sel(joint=joint, angle_deg=slice(lo, hi)).values
        assert np.all(np.abs(pp) < np.abs(a))
        # Every muscle at full activation: the flexors win, so the device must extend (negative).
        assert np.all(a < 0)
    # Hyperextension of the MCP stretches the flexors: holding it takes an extension moment.
    assert float(passive.sel(joint="MCP", angle_deg=-45)) < float(passive.sel(joint="MCP", angle_deg=0))
    # Maximal isometric flexion moments of a middle finger are of the order of N m.
    for joint, ang in (("MCP", 90), ("PIP", 100), ("DIP", 80)):
        assert 0.2 < -float(active.sel(joint=joint, angle_deg=ang)) < 10.0


def test_tone_free_passive_curve_is_a_spring(original):
    """At activation 0 the passive moment is 0 in the straight finger and rises with flexion."""
    tf = original["passive_tone_free_moment_nm"]
    for joint in om.JOINTS:
        lo, hi = om.JOINT_RANGE_DEG[joint]
        curve = tf.sel(joint=joint, angle_deg=slice(0, hi)).values
        assert abs(curve[0]) < 1e-6
        assert np.all(np.diff(curve) > 0), f"{joint}: the relaxed finger must resist flexion more and more"
        # The 1 % tone of the paper's passive state pulls towards flexion: 0.01 lies below 0.
        assert np.all(
            original["moment_nm"].sel(joint=joint, activation=0.01, angle_deg=slice(0, hi)).values < curve + 1e-9
        )
    assert float(tf.sel(joint="MCP", angle_deg=-45)) < 0  # hyperextension: the flexors resist


def test_joint_structures_have_the_published_stiffness(original, params, table):
    """Capsule/ligament/skin spring: k theta with the published stiffness at the mean finger, as OpenSim
    CoordinateLimitForces, and scaled per run by breadth x depth^2 of the joint."""
    k = om.joint_structure_stiffness(params, "F3")
    assert k["MCP"]["flexion"] == pytest.approx(0.0391)  # PMC7775510 Table 2, healthy H1-H4
    assert k["PIP"]["flexion"] == pytest.approx(
        0.05e-2 * 180 / math.pi, rel=1e-3
    )  # Dionysian et al. 2005: 0.05 N cm/deg
    assert 0.3 < k["DIP"]["flexion"] / k["PIP"]["flexion"] < 1.0  # smaller joint, same size law
    js = original["joint_structure_moment_nm"]
    for joint in om.JOINTS:
        lo, hi = om.JOINT_RANGE_DEG[joint]
        for ang in (lo + 10.0 if lo < 0 else 30.0, hi):
            assert float(js.sel(joint=joint, angle_deg=ang)) == pytest.approx(
                k[joint]["flexion" if ang > 0 else "extension"] * math.radians(ang), rel=1e-9
            )
        assert abs(float(js.sel(joint=joint, angle_deg=0.0))) < 1e-12
    # A run's stiffness: the published one times the joint's size factor relative to the mean finger.
    run = factors(table, "D+L+B+")
    ds = ob.sample_finger(params, run, [90.0], (0.01,), ("F3",), factors(table, "Original")).sel(finger="F3")
    ratio = float(
        ds["joint_structure_moment_nm"].sel(joint="PIP", angle_deg=90.0) / js.sel(joint="PIP", angle_deg=90.0)
    )
    ref = factors(table, "Original")
    assert ratio == pytest.approx(om.joint_size_factor(run, "PIP") / om.joint_size_factor(ref, "PIP"), rel=1e-9)
    assert ratio > 1.0  # a bigger finger is stiffer (Dionysian et al. 2005)


def test_passive_at_tone_is_positive_and_rising_beyond_the_resting_posture(original):
    """At the paper's passive activation (0.01) the joint structures and stretched antagonists outweigh
    the flexors' 1 % tone once the joint is flexed beyond its resting angle: holding it there takes a
    positive (flexing) device moment that grows with flexion; the relaxed finger rests flexed, short of
    the exercise targets (straight, it needs a small extension moment: the tone pulls it into flexion)."""
    passive = original["moment_nm"].sel(activation=0.01)
    for joint, target in (("MCP", 90.0), ("PIP", 100.0), ("DIP", 80.0)):
        p = passive.sel(joint=joint, angle_deg=slice(0, target))
        assert np.all(np.diff(p.values) > 0), f"{joint}: must rise with flexion"
        rest = float(p.angle_deg[np.argmax(p.values > 0)])
        assert 5.0 <= rest <= 75.0, f"{joint}: relaxed finger should rest flexed short of the targets ({rest} deg)"
        beyond = p.sel(angle_deg=slice(rest, None))
        assert np.all(beyond.values > 0), f"{joint}: passive must be positive beyond the resting angle"
    for joint, ang in (("MCP", 90.0), ("PIP", 90.0), ("PIP", 100.0), ("DIP", 80.0)):
        assert 0 < float(passive.sel(joint=joint, angle_deg=ang)) < 0.2  # the paper's responses: tens of mN m


def test_gravity_moment_palm_down(original, params):
    g = original["gravity_moment_nm"]
    # Palm down, straight finger: its weight flexes the MCP, so holding it needs extension.
    assert float(g.sel(joint="MCP", angle_deg=0)) < 0
    assert abs(float(g.sel(joint="MCP", angle_deg=90))) < 1e-9  # finger hangs vertically
    # Closed form at 0 deg for the DIP: weight of the DP times its centre's distance.
    dp = params["fingers"]["F3"]["segments_mm"]["DP"]
    m = params["density_kg_m3"]["DP"] * math.pi / 4 * dp["length"] * dp["breadth"] * dp["depth"] * 1e-9
    assert float(g.sel(joint="DIP", angle_deg=0)) == pytest.approx(
        -m * params["gravity_m_s2"] * dp["length"] / 2e3, rel=1e-6
    )


def test_include_gravity_adds_the_holding_moment(params, table, original):
    ref = factors(table, "Original")
    with_g = ob.sample_finger(
        params, ref, original["angle_deg"].values, (0.01, 1.0), ("F3",), ref, include_gravity=True
    ).sel(finger="F3")
    np.testing.assert_allclose(
        with_g["moment_nm"], original["moment_nm"] + original["gravity_moment_nm"], rtol=1e-6, atol=1e-9
    )


def test_opensim_scaling_moves_geometry_and_depth_sets_moment_arms(params, table):
    ref = factors(table, "Original")
    base = om.build_model(params, ("F3",), ref)
    s0 = base.initSystem()
    mass0 = base.getBodySet().get("F3_MP").getMass()
    sf = {b: (1.1, 1.2, 1.3) for b in om.BODIES}
    scaled = ob.scale_model(om.build_model(params, ("F3",), ref), sf, ("F3",))
    s1 = scaled.initSystem()
    # Mass follows the volume (product of the factors); the PIP centre moves with the PP's Y factor.
    assert scaled.getBodySet().get("F3_MP").getMass() == pytest.approx(mass0 * 1.1 * 1.2 * 1.3, rel=1e-9)
    y0 = base.getBodySet().get("F3_MP").getPositionInGround(s0).get(1)
    y1 = scaled.getBodySet().get("F3_MP").getPositionInGround(s1).get(1)
    mc0 = base.getBodySet().get("F3_PP").getPositionInGround(s0).get(1)
    mc1 = scaled.getBodySet().get("F3_PP").getPositionInGround(s1).get(1)
    assert (y1 - mc1) == pytest.approx(1.2 * (y0 - mc0), rel=1e-9)
    # Depth (Z) scales the moment arms in the neutral posture; breadth (X) leaves moments alone.
    d0 = ob.sample_model(om.build_model(params, ("F3",), ref), ("F3",), [0.0], (0.01,))
    deep = ob.sample_finger(params, {b: (1.0, 1.0, 1.2) for b in om.BODIES}, [0.0], (0.01,), ("F3",), ref)
    wide = ob.sample_finger(params, {b: (1.3, 1.0, 1.0) for b in om.BODIES}, [0.0, 90.0], (0.01, 1.0), ("F3",), ref)
    narrow = ob.sample_finger(params, {b: (0.8, 1.0, 1.0) for b in om.BODIES}, [0.0, 90.0], (0.01, 1.0), ("F3",), ref)
    ratio = deep["moment_arm_mm"] / d0["moment_arm_mm"]
    np.testing.assert_allclose(
        ratio.where(np.abs(d0["moment_arm_mm"]) > 0).dropna("joint", how="all").stack(k=ratio.dims).dropna("k"),
        1.2,
        rtol=2e-3,
    )
    # Breadth leaves the muscles alone; it scales the joint structures (breadth x depth^2 law).
    np.testing.assert_allclose(wide["muscle_moment_nm"], narrow["muscle_moment_nm"], rtol=1e-9, atol=1e-12)
    js = wide["joint_structure_moment_nm"].sel(angle_deg=90.0) / narrow["joint_structure_moment_nm"].sel(angle_deg=90.0)
    np.testing.assert_allclose(js.dropna("joint"), 1.3 / 0.8, rtol=1e-9)


@pytest.fixture(scope="module")
def ccd_f3(params, table) -> tuple[xr.Dataset, pd.DataFrame]:
    """Our F3 moments at the 15 CCD runs (response angles only) and the coded levels."""
    ref = factors(table, "Original")
    parts = []
    for run, marker in enumerate(table.index, start=1):
        ds = ob.sample_finger(params, factors(table, marker), [80.0, 90.0, 100.0], (0.01, 1.0), ("F3",), ref)
        parts.append(ds.assign_coords(run=run))
    design = table[["depth", "length", "breadth"]].set_axis(range(1, 16))
    return ob.merge_runs(parts), design


#: Trends of the published export (magnitudes, linear fit on the 15 runs) our model does not
#: reproduce; explained in README "Musculoskeletal model notes": active, the force-length operating
#: point; passive, the joint structures' breadth x depth^2 size law (a deeper, wider finger is stiffer;
#: the export's passive MCP falls with depth and rises with length, its PIP ignores breadth).
KNOWN_TREND_DISAGREEMENTS = {
    ("F3_P_MCP_90", "depth"),
    ("F3_P_MCP_90", "length"),
    ("F3_P_PIP_100", "depth"),
    ("F3_P_PIP_100", "breadth"),
    ("F3_P_PIP_90", "breadth"),
    ("F3_A_MCP_90", "depth"),
    ("F3_A_PIP_100", "depth"),
    ("F3_A_MCP_90", "length"),
    ("F3_A_PIP_100", "length"),
}
F3_RESPONSES = [
    "F3_P_MCP_90",
    "F3_P_PIP_100",
    "F3_P_PIP_90",
    "F3_P_DIP_80",
    "F3_A_MCP_90",
    "F3_A_PIP_100",
    "F3_A_DIP_80",
]


@pytest.mark.parametrize("dimension", ["depth", "length", "breadth"])
@pytest.mark.parametrize("response", F3_RESPONSES)
def test_size_trends_follow_published_data(ccd_f3, authors_moments, response, dimension, request):
    if (response, dimension) in KNOWN_TREND_DISAGREEMENTS:
        request.applymarker(pytest.mark.xfail(strict=True, reason="known disagreement with the ARMS export"))
    ours, design = ccd_f3
    cmp = val.compare(ours, design, val.read_reference(authors_moments))
    assert bool(cmp["trend_agrees"].sel(response=response, dimension=dimension))


def test_breadth_acts_only_through_the_joint_structures(ccd_f3, table):
    """Runs whose depth (Z) and length (Y) factors agree give the same muscle moments, whatever the
    breadth (X) factors (the paper finds breadth has almost no effect); breadth enters only the
    joint structures' stiffness (breadth x depth^2)."""
    ours, _ = ccd_f3
    m = (ours["moment_nm"] - ours["joint_structure_moment_nm"]).sel(finger="F3")
    yz = table[[c for c in table.columns if c.endswith(("_Y", "_Z"))]].round(4)
    groups = yz.reset_index(drop=True).set_axis(range(1, 16)).groupby(list(yz.columns)).groups
    checked = 0
    for runs in groups.values():
        if len(runs) > 1:
            spread = m.sel(run=list(runs)).std("run")
            assert float(spread.max()) < 1e-10
            checked += 1
    assert checked >= 2  # Bm/Original/BM and the corner pairs


def test_validation_compare_identity_and_missing_reference(tmp_path):
    runs = list(range(1, 16))
    rng = np.random.default_rng(3)
    design = pd.DataFrame(rng.uniform(-1, 1, (15, 3)), index=runs, columns=list(val.DIMENSIONS))
    y = 0.1 + 0.05 * design["depth"] - 0.02 * design["length"]
    ours = xr.Dataset(
        {"moment_nm": (("run", "finger", "joint", "angle_deg", "activation"), np.zeros((15, 1, 3, 1, 2)))},
        coords={
            "run": runs,
            "finger": ["F3"],
            "joint": list(om.JOINTS),
            "angle_deg": [90.0],
            "activation": [0.01, 1.0],
        },
    )
    ours["moment_nm"].loc[dict(finger="F3", joint="MCP", angle_deg=90.0, activation=0.01)] = y.to_numpy()
    ref = design.assign(F3_P_MCP_90=y.to_numpy())
    ds = val.compare(ours, design, ref)
    assert float(ds["abs_error"].max()) == 0
    assert bool(ds["sign_agrees"].all())
    np.testing.assert_allclose(ds["slope_ours"].sel(response="F3_P_MCP_90"), [0.05, -0.02, 0.0], atol=1e-12)
    assert float(ds["r2_ours"].sel(response="F3_P_MCP_90", form="linear")) == pytest.approx(1.0)
    # Absent reference: an empty comparison, no crash.
    mpath, cpath = tmp_path / "m.nc", tmp_path / "c.nc"
    ours.to_netcdf(mpath)
    xr.Dataset({d: ("run", design[d].to_numpy()) for d in val.DIMENSIONS}, coords={"run": runs}).to_netcdf(cpath)
    out = entry.write_validation(
        mpath, cpath, tmp_path / "absent.csv", tmp_path / "v.nc", tmp_path / "v.png", rule="test", config_slice={}
    )
    assert out.sizes["response"] == 0 and out.attrs["reference_missing"] == 1
    assert (tmp_path / "v.png").is_file()


def test_run_file_roundtrip_and_merge(params, table, tmp_path):
    """write_run -> netCDF -> merge gives the moments.nc layout with the run's values."""
    ref = factors(table, "Original")
    model = om.write_model(params, tmp_path / "ref.osim", ("F3",), ref)
    scale = np.array([[factors(table, m)[b] for b in om.BODIES] for m in table.index])
    scaling = xr.Dataset(
        {"scale": (("run", "body", "axis"), scale)},
        coords={
            "run": range(1, 16),
            "marker": ("run", list(table.index)),
            "body": list(om.BODIES),
            "axis": ["X", "Y", "Z"],
        },
    )
    scaling.to_netcdf(tmp_path / "scaling.nc")
    files = []
    for run in (9, 12):
        f = tmp_path / f"run{run}.nc"
        entry_opensim.write_run(
            model,
            tmp_path / "scaling.nc",
            run,
            f,
            fingers=("F3",),
            angle_step_deg=45.0,
            activations=(0.01, 1.0),
            include_gravity=False,
            rule="test",
            config_slice={},
        )
        files.append(f)
    merged = entry_opensim.write_merged(files[::-1], tmp_path / "moments.nc", rule="test", config_slice={})
    back = xr.open_dataset(tmp_path / "moments.nc")
    assert list(back["run"].values) == [9, 12]
    assert set(back["moment_nm"].dims) == {"run", "finger", "joint", "angle_deg", "activation"}
    assert {80.0, 90.0, 100.0} <= set(back["angle_deg"].values)
    assert back["moment_nm"].attrs["units"] == "N m"
    xr.testing.assert_allclose(back["moment_nm"], merged["moment_nm"])
    direct = ob.sample_finger(params, factors(table, "DM"), back["angle_deg"].values, (0.01, 1.0), ("F3",), ref)
    # Through the .osim file (text, rounded splines) the model differs slightly from the in-memory one.
    np.testing.assert_allclose(
        back["moment_nm"].sel(run=12, finger="F3"), direct["moment_nm"].sel(finger="F3"), rtol=5e-3, atol=1e-5
    )
    # Outside a joint's range: NaN, status "not_sampled".
    assert np.isnan(float(back["moment_nm"].sel(run=9, finger="F3", joint="DIP", angle_deg=90.0, activation=1.0)))
    assert int(back["status"].sel(run=9, finger="F3", joint="DIP", angle_deg=90.0, activation=1.0)) == 2


def test_patient_from_coded_levels_only(params, config):
    """A patient given only as coded levels (the paper's altered finger) is sampled
    with the scale factors the DOE stage computes; the centre point reproduces the mean finger."""
    from workflow.doe import ccd as doe

    anth = config["anthropometry"]
    levels = pd.DataFrame({"depth": [0.0, 0.5], "length": [0.0, 0.5], "breadth": [0.0, 0.5]}, index=[0, 1])
    scale = doe.scale_factors(levels, config["scaling"], anth["measures"], anth.get("coded_unit_sd", 1.0))
    sf = [{b: tuple(float(v) for v in scale.sel(run=i, body=b).values) for b in om.BODIES} for i in (0, 1)]
    mean = ob.sample_finger(params, sf[0], [0.0, 90.0], (0.01, 1.0), ("F3",), reference_scale=sf[0])
    altered = ob.sample_finger(params, sf[1], [0.0, 90.0], (0.01, 1.0), ("F3",), reference_scale=sf[0])
    arm0 = mean["moment_arm_mm"].sel(finger="F3", muscle="FDP", joint="PIP", angle_deg=0.0)
    assert float(arm0) == pytest.approx(params["fingers"]["F3"]["muscles"]["FDP"]["moment_arms_mm"]["PIP"], rel=1e-3)
    arm1 = altered["moment_arm_mm"].sel(finger="F3", muscle="FDP", joint="PIP", angle_deg=0.0)
    # The PIP pulley sits on the PP: the deeper finger's arm grows with the PP's depth factor.
    assert float(arm1 / arm0) == pytest.approx(sf[1]["PP"][2] / sf[0]["PP"][2], rel=5e-3)
    assert np.all(np.isfinite(altered["moment_nm"].sel(angle_deg=90.0, joint=["MCP", "PIP"])))
