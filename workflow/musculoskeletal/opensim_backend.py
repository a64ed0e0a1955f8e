"""OpenSim backend of the joint moments: scale the generated finger, sample its moments.

For each finger, joint and angle on a grid over the joint's range (the other
joints of the finger at 0 deg) and each activation (0.01 passive, 1.0 active:
every muscle of the finger), the muscles are equilibrated at zero velocity
(Millard2012EquilibriumMuscle: fibre and tendon forces balance) and the net
muscle moment about the joint is the sum of tendon force x moment arm.

Moment arm: the tendon excursion -dL/dq of OpenSim's geometry path (central
difference, +-1e-4 rad, one-sided at the ends of a range, where OpenSim
clamps the moving points' coordinate), the definition An et al. (1983) measured.  OpenSim's
``Muscle.computeMomentArm`` is stored beside it (``opensim_moment_arm_mm``):
with the moving pulley points of our paths it returns exactly half the
excursion (measured; it leaves out the points' dependence on the coordinate,
and OpenSim's force application does the same), so the excursion is used.

Sign (data contract): ``moment_nm`` is the flexion moment
an external device must apply to hold the joint, i.e. minus the net muscle
moment (positive = flexion).  Passive: the stretched antagonists pull back,
so holding a flexed joint needs a positive (flexing) moment.  Active: with
every muscle at full activation the flexors win, so the device must apply an
extension moment: negative.  The gravity moment of the segments (hand
horizontal, palm down) is stored apart in ``gravity_moment_nm`` and added to
``moment_nm`` only when ``include_gravity`` is set (the cascade stage adds gravity from
its own segment volumes).

The passive joint structures (one ``CoordinateLimitForce`` per joint, see
``opensim_model``) are part of the device moment: ``moment_nm`` = -(muscle
moment + joint-structure moment); the latter is stored alone in
``joint_structure_moment_nm``.  ``Model.scale`` leaves coordinate forces alone,
so :func:`scale_model` scales their stiffness by the joint's breadth x depth^2.

The paper's "passive" state is activation 0.01, and so is ours in
``moment_nm``.  At 0.01 the finger's strong flexors carry a 1 % active tone:
the straight finger needs a small extension moment to stay straight (the relaxed
finger rests flexed); beyond that resting angle the joint structures and the
stretched antagonists win and the passive moment is positive and rises with
flexion.  ``passive_tone_free_moment_nm`` is the same curve at activation 0
(passive fibre forces and joint structures, no tone): zero at 0 deg and rising
with flexion, the torsional spring of a relaxed finger.

Over 400 lines: every OpenSim API call (scaling, joint structures, muscles, sampling) sits here, so that only this module touches opensim.
"""

from __future__ import annotations

import logging
import math
import time
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import xarray as xr

from workflow.common.constants import OPENSIM_STATUS
from workflow.musculoskeletal import opensim_model as om

__all__ = [
    "angle_grid",
    "scale_model",
    "load_model",
    "sample_model",
    "sample_finger",
    "sample_run",
    "merge_runs",
    "scale_factors_of_run",
    "reference_scale_factors",
]

log = logging.getLogger(__name__)

_FD_STEP_RAD = 1e-4


def angle_grid(step_deg: float = 5.0, required_deg: Sequence[float] = (0.0, 80.0, 90.0, 100.0)) -> np.ndarray:
    """Common angle coordinate (deg): every joint's range on ``step_deg`` plus the targets in range."""
    vals: set[float] = set()
    for joint, (lo, hi) in om.JOINT_RANGE_DEG.items():
        vals.update(float(v) for v in np.arange(lo, hi + 1e-9, step_deg))
        vals.update(float(a) for a in required_deg if lo <= a <= hi)
    return np.array(sorted(round(v, 6) for v in vals))


def load_model(model_or_path):
    """An ``opensim.Model`` from a path to an ``.osim`` file (or the model itself)."""
    osim = om._opensim()
    if isinstance(model_or_path, (str, Path)):
        return osim.Model(str(model_or_path))
    return model_or_path


def scale_model(model, scale_factors: Mapping[str, Sequence[float]], fingers: Sequence[str]):
    """Scale ``model`` in place with OpenSim's own scaling and return it.

    ``scale_factors[body] = (sX, sY, sZ)`` for body in MC, PP, MP, DP (one
    row of Tables 3-4 / ``scaling.nc``); every finger's bodies get the same
    factors.  ``Model.scale`` moves joint centres, path points (including the
    pulley points' location functions) and wrap objects, scales masses with
    volume and inertias, and rescales each muscle's optimal fibre and tendon
    slack lengths by its change of path length, as the OpenSim GUI does.
    """
    osim = om._opensim()
    scale_set = osim.ScaleSet()
    for finger in fingers:
        for body in om.BODIES:
            sx, sy, sz = (float(v) for v in scale_factors[body])
            sc = osim.Scale()
            sc.setSegmentName(f"{finger}_{body}")
            sc.setScaleFactors(osim.Vec3(sx, sy, sz))
            sc.setApply(True)
            scale_set.cloneAndAppend(sc)
    state = model.initSystem()
    # preserveMassDist=False: masses follow the segments' volume change.
    if not model.scale(state, scale_set, False, -1.0):
        raise RuntimeError("OpenSim Model.scale failed")
    _scale_joint_structures(model, scale_factors, fingers)
    model.initSystem()
    return model


def _joint_structures(model, finger: str) -> dict:
    """The finger's passive joint-structure forces (``CoordinateLimitForce``) by joint (absent ones left out)."""
    osim = om._opensim()
    forces = model.updForceSet()
    out = {}
    for joint in om.JOINTS:
        name = om.joint_structure_name(finger, joint)
        if forces.contains(name):
            out[joint] = osim.CoordinateLimitForce.safeDownCast(forces.get(name))
    return out


def _scale_joint_structures(model, scale_factors: Mapping[str, Sequence[float]], fingers: Sequence[str]) -> None:
    """Scale the joint-structure stiffnesses by breadth x depth^2 of each joint (``om.joint_size_factor``).

    ``Model.scale`` leaves coordinate forces alone; the reference model holds
    the published stiffness divided by the reference run's factor.
    """
    for finger in fingers:
        for joint, clf in _joint_structures(model, finger).items():
            f = om.joint_size_factor(scale_factors, joint)
            clf.set_upper_stiffness(clf.get_upper_stiffness() * f)
            clf.set_lower_stiffness(clf.get_lower_stiffness() * f)


def _finger_muscles(model, finger: str) -> list:
    muscles = model.getMuscles()
    prefix = f"{finger}_"
    return [muscles.get(i) for i in range(muscles.getSize()) if muscles.get(i).getName().startswith(prefix)]


def _vec(v) -> np.ndarray:
    return np.array([v.get(i) for i in range(3)])


def _gravity_holding_moment(bodyset, state, finger: str, joint: str, g_vec: np.ndarray) -> float:
    """Flexion moment (N m) that holds the segments distal of ``joint`` against gravity.

    Minus the moment of the distal bodies' weights about the joint's flexion
    axis (the child's +X through its origin, the joint centre), from OpenSim's
    body poses and inertial properties.
    """
    child = om.JOINT_PARENT_CHILD[joint][1]
    distal = om.BODIES[om.BODIES.index(child) :]
    cbody = bodyset.get(f"{finger}_{child}")
    centre = _vec(cbody.getPositionInGround(state))
    rot = cbody.getTransformInGround(state).R()
    axis = np.array([rot.get(i, 0) for i in range(3)])
    moment = 0.0
    for name in distal:
        b = bodyset.get(f"{finger}_{name}")
        com = _vec(b.findStationLocationInGround(state, b.getMassCenter()))
        moment += float(np.dot(np.cross(com - centre, b.getMass() * g_vec), axis))
    return -moment


def sample_model(
    model,
    fingers: Sequence[str],
    angles_deg: Sequence[float] | None = None,
    activations: Sequence[float] = (0.01, 1.0),
    include_gravity: bool = False,
) -> xr.Dataset:
    """Moment-angle curves of an (already scaled) finger model.

    Returns a Dataset with dims ``finger``, ``joint``, ``angle_deg``,
    ``activation`` (and ``muscle`` for per-muscle variables); values outside a
    joint's range are NaN with ``status`` = 2.  Moments N m, forces N, moment
    arms mm.
    """
    om._opensim()  # fail early, with a clear message, where opensim is missing
    angles = np.asarray(angle_grid() if angles_deg is None else angles_deg, dtype=float)
    acts = np.asarray(activations, dtype=float)
    muscle_names = sorted({m.getName().split("_", 1)[1] for f in fingers for m in _finger_muscles(model, f)})
    nf, nj, na, nact, nm = len(fingers), len(om.JOINTS), len(angles), len(acts), len(muscle_names)
    muscle_moment = np.full((nf, nj, na, nact), np.nan)
    gravity = np.full((nf, nj, na), np.nan)
    tendon = np.full((nf, nm, nj, na, nact), np.nan)
    arm = np.full((nf, nm, nj, na), np.nan)
    arm_osim = np.full((nf, nm, nj, na), np.nan)
    status = np.full((nf, nj, na, nact), 2, dtype=np.int8)
    tone_free = np.full((nf, nj, na), np.nan)
    structures = np.full((nf, nj, na), np.nan)

    state = model.initSystem()
    coords = model.getCoordinateSet()
    bodyset = model.getBodySet()
    g_vec = np.array([model.getGravity().get(i) for i in range(3)])

    for fi, finger in enumerate(fingers):
        fmus = _finger_muscles(model, finger)
        mindex = [muscle_names.index(m.getName().split("_", 1)[1]) for m in fmus]
        fcoords = [coords.get(om.joint_coordinate_name(finger, j)) for j in om.JOINTS]
        fstruct = _joint_structures(model, finger)
        for ji, joint in enumerate(om.JOINTS):
            lo, hi = om.JOINT_RANGE_DEG[joint]
            coord = fcoords[ji]
            for ai, ang in enumerate(angles):
                if not lo - 1e-9 <= ang <= hi + 1e-9:
                    continue
                for c in fcoords:
                    c.setValue(state, 0.0, False)
                q = math.radians(ang)
                # Tendon excursion: path lengths either side of the angle.
                # OpenSim evaluates moving path points at the coordinate clamped to
                # its range, so the difference stays inside the range (one-sided at an end).
                q_lo = max(q - _FD_STEP_RAD, math.radians(lo))
                q_hi = min(q + _FD_STEP_RAD, math.radians(hi))
                lengths = []
                for qq in (q_lo, q_hi):
                    coord.setValue(state, qq, False)
                    model.realizePosition(state)
                    lengths.append([m.getLength(state) for m in fmus])
                coord.setValue(state, q, False)
                model.realizePosition(state)
                exc = -(np.array(lengths[1]) - np.array(lengths[0])) / (q_hi - q_lo)
                for k, m in enumerate(fmus):
                    arm[fi, mindex[k], ji, ai] = exc[k] * 1000.0
                    arm_osim[fi, mindex[k], ji, ai] = m.computeMomentArm(state, coord) * 1000.0
                gravity[fi, ji, ai] = _gravity_holding_moment(bodyset, state, finger, joint, g_vec)
                # Passive joint structures: the device balances their (generalised) moment.
                if joint in fstruct:
                    model.realizeVelocity(state)
                    structures[fi, ji, ai] = -float(fstruct[joint].calcLimitForce(state))
                else:
                    structures[fi, ji, ai] = 0.0
                for bi, a in enumerate([*acts, 0.0]):
                    for m in fmus:
                        m.setActivation(state, float(a))
                    try:
                        model.equilibrateMuscles(state)
                        model.realizeDynamics(state)
                        forces = np.array([m.getTendonForce(state) for m in fmus])
                    except RuntimeError as err:  # OpenSim raises on a failed fibre equilibrium
                        log.warning("%s %s %.1f deg a=%.2f: equilibrium failed: %s", finger, joint, ang, a, err)
                        if bi < nact:
                            status[fi, ji, ai, bi] = 1
                        continue
                    if bi == nact:  # activation 0: the fibres' passive force and the joint structures
                        tone_free[fi, ji, ai] = -float(np.sum(forces * exc)) + structures[fi, ji, ai]
                        continue
                    for k in range(len(fmus)):
                        tendon[fi, mindex[k], ji, ai, bi] = forces[k]
                    muscle_moment[fi, ji, ai, bi] = float(np.sum(forces * exc))
                    status[fi, ji, ai, bi] = 0
                coord.setValue(state, 0.0, False)

    device = -muscle_moment + structures[..., None]
    if include_gravity:
        device = device + gravity[..., None]
    coords_ = {
        "finger": list(fingers),
        "joint": list(om.JOINTS),
        "angle_deg": ("angle_deg", angles, {"units": "degree", "long_name": "joint flexion angle"}),
        "activation": ("activation", acts, {"units": "1", "long_name": "muscle activation"}),
        "muscle": muscle_names,
    }
    fjaa = ("finger", "joint", "angle_deg", "activation")
    ds = xr.Dataset(
        {
            "moment_nm": (
                fjaa,
                device,
                {
                    "units": "N m",
                    "long_name": "flexion moment an external device must apply to hold the joint "
                    "(other joints at 0 deg; muscles and passive joint structures"
                    + (", gravity included)" if include_gravity else ", gravity excluded)"),
                },
            ),
            "passive_tone_free_moment_nm": (
                ("finger", "joint", "angle_deg"),
                tone_free,
                {
                    "units": "N m",
                    "long_name": "flexion moment a device must apply to hold the joint with every muscle at "
                    "activation 0 (passive fibre and tendon forces and joint structures, no 1 % tone)",
                },
            ),
            "joint_structure_moment_nm": (
                ("finger", "joint", "angle_deg"),
                structures,
                {
                    "units": "N m",
                    "long_name": "flexion moment a device must apply against the passive joint structures "
                    "(capsule, ligaments, skin; included in moment_nm)",
                },
            ),
            "muscle_moment_nm": (
                fjaa,
                muscle_moment,
                {
                    "units": "N m",
                    "long_name": "net flexion moment of the finger's muscles about the joint "
                    "(joint structures excluded)",
                },
            ),
            "gravity_moment_nm": (
                ("finger", "joint", "angle_deg"),
                gravity,
                {
                    "units": "N m",
                    "long_name": "flexion moment needed to hold the segments against gravity (hand horizontal, palm down)",
                },
            ),
            "tendon_force_n": (
                ("finger", "muscle", "joint", "angle_deg", "activation"),
                tendon,
                {"units": "N", "long_name": "tendon force at static equilibrium"},
            ),
            "moment_arm_mm": (
                ("finger", "muscle", "joint", "angle_deg"),
                arm,
                {"units": "mm", "long_name": "flexion moment arm, tendon excursion -dL/dq"},
            ),
            "opensim_moment_arm_mm": (
                ("finger", "muscle", "joint", "angle_deg"),
                arm_osim,
                {"units": "mm", "long_name": "OpenSim Muscle.computeMomentArm (halves moving-point terms)"},
            ),
            "status": (
                fjaa,
                status,
                {
                    "long_name": "sample status",
                    "flag_values": np.array(list(OPENSIM_STATUS), dtype=np.int8),
                    "flag_meanings": " ".join(OPENSIM_STATUS.values()),
                },
            ),
        },
        coords=coords_,
    )
    ds.attrs["include_gravity"] = int(include_gravity)
    return ds


def sample_finger(
    model_path_or_params,
    scale_factors: Mapping[str, Sequence[float]] | None,
    angles_deg: Sequence[float] | None = None,
    activations: Sequence[float] = (0.01, 1.0),
    fingers: Sequence[str] = ("F3",),
    reference_scale: Mapping[str, Sequence[float]] | None = None,
    include_gravity: bool = False,
) -> xr.Dataset:
    """Moment-angle curves of one finger scaled by ``scale_factors`` (e.g. one patient).

    ``model_path_or_params``: a reference ``.osim`` written by
    :func:`workflow.musculoskeletal.opensim_model.write_model`, or the parameter
    file (path or dict) to build it from (then ``reference_scale`` is the
    ``Original`` row, see ``opensim_model``).  ``scale_factors``: ``{body: (sX,
    sY, sZ)}``; ``None`` leaves the model unscaled.
    """
    src = model_path_or_params
    if isinstance(src, Mapping):
        model = om.build_model(src, fingers, reference_scale)
    elif str(src).endswith((".yaml", ".yml")):
        model = om.build_model(om.load_parameters(src), fingers, reference_scale)
    else:
        model = load_model(src)
    if scale_factors is not None:
        scale_model(model, scale_factors, fingers)
    return sample_model(model, fingers, angles_deg, activations, include_gravity)


def sample_run(
    model_path: str | Path,
    scale_factors: Mapping[str, Sequence[float]],
    run: int,
    fingers: Sequence[str],
    angles_deg: Sequence[float] | None = None,
    activations: Sequence[float] = (0.01, 1.0),
    include_gravity: bool = False,
) -> xr.Dataset:
    """One CCD run: scale the reference model by the run's factors and sample it.

    Adds the scalar coordinate ``run`` and the wall time (``wall_time_s``).
    """
    t0 = time.perf_counter()
    ds = sample_finger(model_path, scale_factors, angles_deg, activations, fingers, include_gravity=include_gravity)
    ds = ds.assign_coords(run=int(run))
    ds["wall_time_s"] = ((), time.perf_counter() - t0, {"units": "s", "long_name": "sampling wall time"})
    ds["scale"] = (
        ("body", "axis"),
        np.array([[float(v) for v in scale_factors[b]] for b in om.BODIES]),
        {"units": "1", "long_name": "OpenSim scale factor applied"},
    )
    ds = ds.assign_coords(body=list(om.BODIES), axis=["X", "Y", "Z"])
    return ds


def merge_runs(datasets: Sequence[xr.Dataset]) -> xr.Dataset:
    """Stack per-run datasets along ``run`` (sorted) into the ``moments.nc`` layout."""
    ds = xr.concat(
        list(datasets),
        dim="run",
        data_vars="all",
        coords="different",
        compat="equals",
        join="outer",
        combine_attrs="drop_conflicts",
    )
    ds = ds.sortby("run")
    ds["run"].attrs.update({"long_name": "CCD run number"})
    return ds


def scale_factors_of_run(scaling: xr.Dataset, run: int) -> dict[str, tuple[float, float, float]]:
    """``{body: (sX, sY, sZ)}`` of one run of ``scaling.nc`` (var ``scale``, dims run, body, axis)."""
    sc = scaling["scale"].sel(run=run)
    return {b: tuple(float(sc.sel(body=b, axis=a)) for a in ("X", "Y", "Z")) for b in om.BODIES}


# --- Path-level entry points of the Snakemake rules -------------------------------------------


def reference_scale_factors(scaling: xr.Dataset, marker: str = "Original") -> dict[str, tuple[float, float, float]]:
    """Scale factors of the run labelled ``marker`` (the centre point: the mean finger)."""
    markers = [str(m) for m in scaling["marker"].values]
    if marker not in markers:
        raise ValueError(f"no run with marker {marker!r} in the scaling table (markers: {markers})")
    return scale_factors_of_run(scaling, int(scaling["run"].values[markers.index(marker)]))
