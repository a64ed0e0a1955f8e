"""Generated OpenSim finger model: bodies, joints and muscles from parameters.

The model holds one independent chain per finger (``F2`` index .. ``F5``
little): a metacarpal ``{finger}_MC`` welded to ground and the phalanges
``{finger}_PP``, ``{finger}_MP``, ``{finger}_DP`` on flexion-extension pin
joints ``{finger}_MCP`` (-45..90 deg), ``{finger}_PIP`` (0..100 deg) and
``{finger}_DIP`` (0..80 deg).

Body frames follow the axis meaning of the paper's OpenSim scale factors
(Tables 3-4, ARMS model): ``Y`` runs along the bone and points proximally
(the bone extends along -Y from its proximal joint centre), ``Z`` is dorsal
(+) / palmar (-), so it carries the finger *depth*, and ``X = Y x Z`` is the
flexion axis across the finger, so it carries the *breadth*.  A positive
rotation about +X moves the distal segment palmarwards: positive coordinate
value = flexion, as in the data contract.  Ground coincides with the
metacarpal frames; the hand lies horizontal, palm down, so gravity acts along
ground -Z (palmar).

Muscles (Millard2012EquilibriumMuscle: active and passive force-length,
compliant tendon) run along via points on each side of every joint they cross
and wrap over a cylinder centred on the joint axis whose radius is the
published moment arm: a flexor wraps a palmar cylinder, an extensor a dorsal
one, so each crossing keeps its moment arm over the range of motion, like a
tendon held by its pulley.  Extrinsic muscles (FDS, FDP, EDC) originate on
ground ``forearm_length_mm`` proximal of the MCP (the forearm is not scaled);
the lumbrical originates on the palmar metacarpal.

Passive joint structures (capsule, collateral ligaments, volar plate, skin):
one OpenSim ``CoordinateLimitForce`` per joint (``{finger}_{joint}_joint_structures``)
with both limits at the neutral angle, i.e. a linear spring with the published
in-vivo passive stiffness of the joint (``joint_structures`` in the parameter
file), scaled per CCD run by the joint's breadth x depth^2
(:func:`joint_size_factor`).

The *reference* (unscaled) model is the mean finger divided, axis by axis, by
the scale factors of the CCD's ``Original`` run: the paper scaled a generic
model whose marker distances are not published, so we infer it from that row
.  Scaling the reference model by a run's Table 3-4
factors then gives that run's finger, and the ``Original`` run gives the mean
finger.

Units: lengths in the parameter file are mm (moment arms, segment
dimensions), forces N, fibre lengths m, angles deg, densities kg m-3; the
OpenSim model itself is in SI units (m, kg, N, rad).

Over 400 lines: most of it is the finger's parameter tables (bodies, joints, muscle paths) written out once, beside the code that builds the model from them.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import yaml

from ..common.constants import JOINTS

__all__ = [
    "BODIES",
    "JOINT_PARENT_CHILD",
    "JOINT_RANGE_DEG",
    "FINGERS",
    "load_parameters",
    "reference_dimensions_m",
    "build_model",
    "write_model",
    "joint_coordinate_name",
    "muscle_name",
    "joint_structure_name",
    "joint_structure_stiffness",
    "joint_size_factor",
]

BODIES = ("MC", "PP", "MP", "DP")
JOINT_PARENT_CHILD = {"MCP": ("MC", "PP"), "PIP": ("PP", "MP"), "DIP": ("MP", "DP")}
#: Ranges of motion used by the paper (section 2.2), deg.
JOINT_RANGE_DEG = {"MCP": (-45.0, 90.0), "PIP": (0.0, 100.0), "DIP": (0.0, 80.0)}
FINGERS = ("F2", "F3", "F4", "F5")
#: Axis of each body-frame direction in the scale-factor tables.
_AXES = ("X", "Y", "Z")


def _opensim():
    import opensim as osim  # imported lazily: heavy, and only the OpenSim backend needs it

    osim.Logger.setLevelString("error")
    return osim


def joint_coordinate_name(finger: str, joint: str) -> str:
    """Name of the flexion coordinate of ``joint`` of ``finger`` (e.g. ``F3_MCP_flex``)."""
    return f"{finger}_{joint}_flex"


def muscle_name(finger: str, muscle: str) -> str:
    """Name of ``muscle`` (e.g. ``FDP``) of ``finger`` in the model (e.g. ``F3_FDP``)."""
    return f"{finger}_{muscle}"


def joint_structure_name(finger: str, joint: str) -> str:
    """Name of the passive joint-structure force of ``joint`` of ``finger`` (e.g. ``F3_PIP_joint_structures``)."""
    return f"{finger}_{joint}_joint_structures"


def joint_size_factor(scale: Mapping[str, Sequence[float]], joint: str) -> float:
    """Factor by which a joint's passive-structure stiffness scales with the segments' scale factors.

    The capsule, collateral ligaments, volar plate and skin span the joint: a
    tissue band of cross-section ~ joint breadth x joint depth, stretched at a
    lever arm ~ joint depth by a strain ~ (depth x angle) / (tissue length ~
    depth), so the moment per radian scales as breadth x depth^2.  Joint breadth
    and depth are the geometric means of the two adjacent segments', hence
    ``sqrt(sX_p sX_c) * sZ_p * sZ_c`` (p, c = parent and child body).
    """
    parent, child = JOINT_PARENT_CHILD[joint]
    sxp, _, szp = (float(v) for v in scale[parent])
    sxc, _, szc = (float(v) for v in scale[child])
    return math.sqrt(sxp * sxc) * szp * szc


def _joint_breadth_depth2(params: Mapping[str, Any], finger: str, joint: str) -> float:
    """breadth x depth^2 (mm^3) of a joint of ``finger``: geometric means of the adjacent segments' dimensions."""
    seg = params["fingers"][finger]["segments_mm"]
    parent, child = JOINT_PARENT_CHILD[joint]
    b = math.sqrt(seg[parent]["breadth"] * seg[child]["breadth"])
    d2 = seg[parent]["depth"] * seg[child]["depth"]
    return b * d2


def joint_structure_stiffness(params: Mapping[str, Any], finger: str) -> dict[str, dict[str, float]]:
    """Passive joint-structure stiffness of each joint of ``finger`` at its configured (mean) size, N m/rad.

    ``{joint: {"flexion": k_f, "extension": k_e}}`` from the ``joint_structures``
    section of the parameter file.  A joint given as ``derived_from: PIP``
    takes that joint's published stiffness times the ratio of the joints'
    breadth x depth^2 (:func:`joint_size_factor`'s scaling law, applied between
    joints of the mean finger).  Empty when the section is absent.
    """
    spec = params.get("joint_structures") or {}
    joints = spec.get("joints") or {}
    out: dict[str, dict[str, float]] = {}
    for joint in JOINTS:
        js = joints.get(joint)
        if js is None:
            continue
        if "derived_from" in js:
            src = joints[js["derived_from"]]
            ratio = _joint_breadth_depth2(params, finger, joint) / _joint_breadth_depth2(
                params, finger, js["derived_from"]
            )
            kf = float(src["stiffness_nm_per_rad"]) * ratio
            ke = float(src.get("extension_stiffness_nm_per_rad", src["stiffness_nm_per_rad"])) * ratio
        else:
            kf = float(js["stiffness_nm_per_rad"])
            ke = float(js.get("extension_stiffness_nm_per_rad", kf))
        out[joint] = {"flexion": kf, "extension": ke}
    return out


def load_parameters(path: str | Path) -> dict[str, Any]:
    """Read and check the finger parameter file (``config/finger_muscles.yaml``).

    Raises ``ValueError`` on a missing or inconsistent entry, so that a typo
    fails before OpenSim is involved.
    """
    with open(path) as fh:
        params = yaml.safe_load(fh)
    _check_parameters(params)
    return params


def _check_parameters(params: Mapping[str, Any]) -> None:
    for key in ("forearm_length_mm", "density_kg_m3", "fingers"):
        if key not in params:
            raise ValueError(f"finger parameters: missing key {key!r}")
    for finger, fp in params["fingers"].items():
        if finger not in FINGERS:
            raise ValueError(f"finger parameters: unknown finger {finger!r}")
        for body in BODIES:
            dims = fp["segments_mm"][body]
            for k in ("length", "breadth", "depth"):
                if not dims[k] > 0:
                    raise ValueError(f"{finger} {body} {k} must be > 0 mm")
        for mname, mp in fp["muscles"].items():
            arms = mp["moment_arms_mm"]
            crossed = [j for j in JOINTS if j in arms]
            if not crossed or crossed != list(
                JOINTS[JOINTS.index(crossed[0]) : JOINTS.index(crossed[0]) + len(crossed)]
            ):
                raise ValueError(f"{finger} {mname}: crossed joints must be consecutive, got {list(arms)}")
            if any(a == 0 for a in arms.values()):
                raise ValueError(f"{finger} {mname}: a moment arm of 0 mm is not a crossing")
            for k in ("max_isometric_force", "optimal_fiber_length", "fiber_length_at_neutral"):
                if not mp[k] > 0:
                    raise ValueError(f"{finger} {mname}: {k} must be > 0")
            if mp.get("origin", "forearm") not in ("forearm", "MC"):
                raise ValueError(f"{finger} {mname}: origin must be 'forearm' or 'MC'")
    joints = (params.get("joint_structures") or {}).get("joints") or {}
    for joint, js in joints.items():
        if joint not in JOINTS:
            raise ValueError(f"joint_structures: unknown joint {joint!r}")
        if "derived_from" in js:
            src = joints.get(js["derived_from"])
            if src is None or "derived_from" in src:
                raise ValueError(f"joint_structures {joint}: derived_from must name a joint with its own stiffness")
        else:
            for k in ("stiffness_nm_per_rad", "extension_stiffness_nm_per_rad"):
                if k in js and not float(js[k]) >= 0:
                    raise ValueError(f"joint_structures {joint}: {k} must be >= 0")
            if "stiffness_nm_per_rad" not in js:
                raise ValueError(f"joint_structures {joint}: stiffness_nm_per_rad or derived_from required")


def reference_dimensions_m(
    params: Mapping[str, Any], finger: str, reference_scale: Mapping[str, Sequence[float]] | None
) -> dict[str, dict[str, float]]:
    """Segment length/breadth/depth of the reference (unscaled) model, m.

    ``reference_scale[body] = (sX, sY, sZ)`` is the ``Original`` row of the
    scale-factor table; breadth is divided by sX, length by sY and depth by sZ.
    ``None`` builds the mean finger itself (all factors 1).
    """
    out: dict[str, dict[str, float]] = {}
    for body in BODIES:
        d = params["fingers"][finger]["segments_mm"][body]
        sx, sy, sz = reference_scale[body] if reference_scale is not None else (1.0, 1.0, 1.0)
        out[body] = {
            "length": d["length"] / 1000.0 / sy,
            "breadth": d["breadth"] / 1000.0 / sx,
            "depth": d["depth"] / 1000.0 / sz,
        }
    return out


def _segment_inertia(mass: float, length: float, breadth: float, depth: float) -> tuple[float, float, float]:
    """Principal moments (Ixx, Iyy, Izz) of a solid elliptic cylinder along Y about its centre, kg m2."""
    a, b = breadth / 2.0, depth / 2.0
    ixx = mass * (length**2 / 12.0 + b**2 / 4.0)
    iyy = mass * (a**2 + b**2) / 4.0
    izz = mass * (length**2 / 12.0 + a**2 / 4.0)
    return ixx, iyy, izz


def _add_finger(
    osim,
    model,
    params: Mapping[str, Any],
    finger: str,
    dims: Mapping[str, Mapping[str, float]],
    ref: Mapping[str, Sequence[float]],
):
    fp = params["fingers"][finger]
    ground = model.getGround()
    bodies = {}
    for body in BODIES:
        L, B, D = dims[body]["length"], dims[body]["breadth"], dims[body]["depth"]
        rho = float(params["density_kg_m3"][body])
        # Volume of an elliptic cylinder of the segment's skin dimensions.
        mass = rho * math.pi / 4.0 * B * D * L
        ixx, iyy, izz = _segment_inertia(mass, L, B, D)
        b = osim.Body(f"{finger}_{body}", mass, osim.Vec3(0, -L / 2.0, 0), osim.Inertia(ixx, iyy, izz))
        model.addBody(b)
        bodies[body] = b

    weld = osim.WeldJoint(
        f"{finger}_ground_MC", ground, osim.Vec3(0), osim.Vec3(0), bodies["MC"], osim.Vec3(0), osim.Vec3(0)
    )
    model.addJoint(weld)
    for joint in JOINTS:
        parent, child = JOINT_PARENT_CHILD[joint]
        Lp = dims[parent]["length"]
        # Pin joints rotate about their frames' Z axis; turning the joint frames
        # by +90 deg about Y maps that Z onto the bodies' +X (the flexion axis).
        rot = osim.Vec3(0, math.pi / 2.0, 0)
        pin = osim.PinJoint(
            f"{finger}_{joint}", bodies[parent], osim.Vec3(0, -Lp, 0), rot, bodies[child], osim.Vec3(0), rot
        )
        coord = pin.upd_coordinates(0)
        coord.setName(joint_coordinate_name(finger, joint))
        lo, hi = JOINT_RANGE_DEG[joint]
        coord.setRangeMin(math.radians(lo))
        coord.setRangeMax(math.radians(hi))
        coord.setDefaultValue(0.0)
        # Sampling sets angles inside the range; clamping would only hide mistakes.
        coord.setDefaultClamped(False)
        model.addJoint(pin)

    _add_joint_structures(osim, model, params, finger, ref)

    forearm = params["forearm_length_mm"] / 1000.0
    coords = {j: model.getCoordinateSet().get(joint_coordinate_name(finger, j)) for j in JOINTS}
    for mname, mp in fp["muscles"].items():
        arms = {j: float(v) / 1000.0 for j, v in mp["moment_arms_mm"].items()}  # + flexion, - extension
        crossed = [j for j in JOINTS if j in arms]
        # Palmar (flexing) offset is -Z, dorsal (extending) +Z.
        z = {j: -arms[j] for j in crossed}
        mus = osim.Millard2012EquilibriumMuscle(
            muscle_name(finger, mname),
            float(mp["max_isometric_force"]),
            float(mp["optimal_fiber_length"]),
            1.0,  # tendon slack length: set after assembly from the neutral path length
            math.radians(float(mp.get("pennation_deg", 0.0))),
        )
        first = crossed[0]
        parent0 = JOINT_PARENT_CHILD[first][0]

        def at(body: str, y: float, zz: float):
            # Path geometry is laid out on the mean finger; each body's
            # reference frame holds it divided by that body's reference factors.
            _, sy, sz = ref[body]
            return osim.Vec3(0, y / sy, zz / sz)

        mean_len = {b: dims[b]["length"] * ref[b][1] for b in BODIES}
        if mp.get("origin", "forearm") == "forearm":
            mus.addNewPathPoint(f"{mus.getName()}_origin", ground, osim.Vec3(0, forearm, z[first]))
        else:
            mus.addNewPathPoint(
                f"{mus.getName()}_origin", bodies[parent0], at(parent0, -0.5 * mean_len[parent0], z[first])
            )
        for joint in crossed:
            parent, child = JOINT_PARENT_CHILD[joint]
            r = abs(arms[joint])
            h = _PULLEY_REACH * r
            Lp = mean_len[parent]
            fy, fz = _pulley_functions(osim, r, h, flexor=arms[joint] > 0)
            fy = _affine(osim, fy, -Lp, 1.0 / ref[parent][1])
            fz = _affine(osim, fz, 0.0, 1.0 / ref[parent][2])
            mus.addNewPathPoint(f"{mus.getName()}_{joint}_prox", bodies[parent], at(parent, -Lp + h, z[joint]))
            mpp = osim.MovingPathPoint()
            mpp.setName(f"{mus.getName()}_{joint}_pulley")
            mpp.setParentFrame(bodies[parent])
            for axis, func in (("x", osim.Constant(0.0)), ("y", fy), ("z", fz)):
                getattr(mpp, f"set_{axis}_location")(func)
                getattr(mpp, f"set{axis.upper()}Coordinate")(coords[joint])
            mus.updGeometryPath().updPathPointSet().adoptAndAppend(mpp)
            mus.addNewPathPoint(f"{mus.getName()}_{joint}_dist", bodies[child], at(child, -h, z[joint]))
        last_child = JOINT_PARENT_CHILD[crossed[-1]][1]
        # Insertion at the base of the last segment crossed, beyond the distal via point.
        ins_y = -min(2.0 * _PULLEY_REACH * abs(arms[crossed[-1]]), 0.5 * mean_len[last_child])
        mus.addNewPathPoint(f"{mus.getName()}_insertion", bodies[last_child], at(last_child, ins_y, z[crossed[-1]]))
        mus.set_default_fiber_length(float(mp["optimal_fiber_length"]))
        # OpenSim's default floor of 0.01 would make the paper's "passive" state
        # (activation 0.01) the lowest possible; 0 allows the tone-free passive curve.
        mus.set_minimum_activation(0.0)
        model.addForce(mus)


def _add_joint_structures(
    osim, model, params: Mapping[str, Any], finger: str, ref: Mapping[str, Sequence[float]]
) -> None:
    """Passive joint structures (capsule, ligaments, volar plate, skin) as one force per joint.

    An OpenSim ``CoordinateLimitForce`` with both limits at the neutral angle
    (``rest_angle_deg``, 0 by default) is a spring on the joint coordinate:
    moment -k_f (q - q0) in flexion, -k_e (q - q0) in extension (linear beyond a
    ``transition_deg`` ramp), no damping (statics).  The published stiffness
    applies to the mean finger; the reference model holds it divided by the
    ``Original`` run's size factor, so that scaling by a run's factors
    (``opensim_backend.scale_model``) gives that run's stiffness and the
    ``Original`` run the published one.
    """
    spec = params.get("joint_structures") or {}
    stiff = joint_structure_stiffness(params, finger)
    q0 = float(spec.get("rest_angle_deg", 0.0))
    transition = float(spec.get("transition_deg", 1.0))
    for joint, k in stiff.items():
        f = joint_size_factor(ref, joint)
        deg = math.pi / 180.0  # CoordinateLimitForce takes stiffness per degree for rotational coordinates
        clf = osim.CoordinateLimitForce(
            joint_coordinate_name(finger, joint),
            q0,
            k["flexion"] / f * deg,
            q0,
            k["extension"] / f * deg,
            0.0,
            transition,
        )
        clf.setName(joint_structure_name(finger, joint))
        model.addForce(clf)


#: Via points sit this many moment arms proximal and distal of each joint axis.
_PULLEY_REACH = 1.5
#: Angle grid (deg) on which the pulley point's offset is tabulated; covers every range.
_PULLEY_GRID_DEG = np.arange(-70.0, 130.0 + 1e-9, 2.0)


def _pulley_offsets(r: float, h: float, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position (along the bone, dorsal) of a flexor's pulley point that keeps its moment arm ``r``.

    The tendon runs from a via point (h, -r) on the proximal segment, through
    the pulley point V on the bisector of the joint angle (a point of the
    proximal segment that moves with the joint angle, like a tendon sheath),
    to the mirror-image via point (-h, -r) on the distal segment, rotated by
    ``theta`` (rad) about the joint axis at the origin (m).  Its length must be
    2h - r theta, i.e. -dL/dtheta = r at every angle: the sheath keeps the
    tendon from bowstringing in flexion and off the joint in hyperextension.
    With u = (sin theta/2, -cos theta/2) and V = rho u, |P1 - V| = h - r theta/2
    has the roots rho = P1.u -+ sqrt((h - r theta/2)^2 - (P1 x u)^2); the
    branch through rho = r at theta = 0 is the one nearest r.
    Returns (y, z) offsets from the joint centre, m.
    """
    u_y, u_z = np.sin(theta / 2.0), -np.cos(theta / 2.0)
    foot = h * u_y + r * np.cos(theta / 2.0)  # P1 . u
    dist2 = (h * u_z - (-r) * u_y) ** 2  # (P1 x u)^2
    half = h - r * theta / 2.0
    disc = np.sqrt(np.maximum(half**2 - dist2, 0.0))
    roots = np.stack([foot - disc, foot + disc])
    rho = roots[np.argmin(np.abs(roots - r), axis=0), np.arange(theta.size)]
    return rho * u_y, rho * u_z


def _affine(osim, spline, offset: float, factor: float):
    """The spline with values (y + offset) * factor (joint position; reference-frame factor)."""
    out = osim.SimmSpline()
    for i in range(spline.getSize()):
        out.addPoint(spline.getX(i), (spline.getY(i) + offset) * factor)
    return out


def _pulley_functions(osim, r: float, h: float, flexor: bool):
    """OpenSim splines of the pulley point's (Y, Z) offsets against the joint angle (rad).

    An extensor is the mirror image of a flexor (Z -> -Z, theta -> -theta).
    """
    theta = np.radians(_PULLEY_GRID_DEG)
    if flexor:
        ys, zs = _pulley_offsets(r, h, theta)
    else:
        ys, zs = _pulley_offsets(r, h, -theta)
        zs = -zs
    fy, fz = osim.SimmSpline(), osim.SimmSpline()
    for t, yy, zz in zip(theta, ys, zs):
        fy.addPoint(float(t), float(yy))
        fz.addPoint(float(t), float(zz))
    return fy, fz


def _set_tendon_slack_lengths(osim, model, params: Mapping[str, Any], fingers: Sequence[str]) -> None:
    """Tendon slack length so that each fibre has its given normalised length at the neutral posture.

    With an inextensible tendon at slack (no force in the neutral posture):
    L_mt = l_ts + l_f cos(alpha), and the Millard model keeps the fibre's
    height l_opt sin(alpha_opt) constant, so l_f cos(alpha) =
    sqrt(l_f^2 - (l_opt sin alpha_opt)^2) with l_f = lambda0 l_opt.
    """
    state = model.initSystem()
    model.realizePosition(state)
    for finger in fingers:
        for mname, mp in params["fingers"][finger]["muscles"].items():
            mus = osim.Millard2012EquilibriumMuscle.safeDownCast(model.updMuscles().get(muscle_name(finger, mname)))
            lopt = float(mp["optimal_fiber_length"])
            lam0 = float(mp["fiber_length_at_neutral"])
            height = lopt * math.sin(math.radians(float(mp.get("pennation_deg", 0.0))))
            along = math.sqrt((lam0 * lopt) ** 2 - height**2)
            lmt = mus.getLength(state)
            lts = lmt - along
            if lts <= 0:
                raise ValueError(f"{finger} {mname}: path too short for its fibre ({lmt:.4f} m)")
            mus.set_tendon_slack_length(lts)


def build_model(
    params: Mapping[str, Any],
    fingers: Sequence[str] = ("F3",),
    reference_scale: Mapping[str, Sequence[float]] | None = None,
):
    """The reference finger model (``opensim.Model``), ready for scaling and sampling.

    Parameters
    ----------
    params : the parameter file's content (see :func:`load_parameters`).
    fingers : fingers to build (``F2`` .. ``F5``); each is an independent chain.
    reference_scale : ``{body: (sX, sY, sZ)}`` of the CCD's ``Original`` run;
        the reference model is the mean finger divided by it (``None``: the
        mean finger itself).
    """
    osim = _opensim()
    model = osim.Model()
    model.setName("finger_" + "_".join(fingers))
    model.set_credits("finger-rehab-workflow: generated from config/finger_muscles.yaml")
    g = float(params.get("gravity_m_s2", 9.80665))
    # Hand horizontal, palm down: gravity along -Z of the metacarpal (palmar).
    model.setGravity(osim.Vec3(0, 0, -g))
    for finger in fingers:
        ref = reference_scale if reference_scale is not None else {b: (1.0, 1.0, 1.0) for b in BODIES}
        _add_finger(osim, model, params, finger, reference_dimensions_m(params, finger, reference_scale), ref)
    model.finalizeConnections()
    _set_tendon_slack_lengths(osim, model, params, fingers)
    model.finalizeConnections()
    return model


def write_model(
    params: Mapping[str, Any],
    path: str | Path,
    fingers: Sequence[str] = ("F3",),
    reference_scale: Mapping[str, Sequence[float]] | None = None,
) -> Path:
    """Build the reference model and write it as an ``.osim`` file (atomic)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    model = build_model(params, fingers, reference_scale)
    tmp = path.with_name(path.stem + ".part.osim")
    model.printToXML(str(tmp))
    tmp.replace(path)
    return path
