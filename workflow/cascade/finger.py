"""Planar three-phalanx finger: geometry, masses, joint springs, gravity droop.

The finger lies in its sagittal plane.  Coordinates: ``x`` along the finger
from the MCP joint centre towards the tip, ``y`` dorsal.  The hand is
horizontal, palm down, so gravity points along ``-y`` and
flexes the finger.  A joint angle is positive in flexion: the distal segment
turns clockwise in this frame.  The metacarpal is fixed (it is the hand).

Segments (PP, MP, DP) are rigid.  Their lengths are the patient's L3PP, L3MP,
L3DP; the joint centres sit below a flat dorsal line at the depths read from
the authors' section points (``finger_section_points_mean_finger.csv``:
10.14, 8.43 and 5.67 mm for MCP, PIP, DIP -- the moment arms of the paper's
dummy finger) scaled by the patient's D3MCP, D3PIP, D3DIP.  Masses come from a
depth profile (the section points, scaled per segment by D3PP, D3MP, D3DP)
times the patient's breadths (Table 2 B3 codes) with elliptic cross-sections,
flesh and bone densities of the paper (section 3.2).  Without the section file
each segment is an elliptic cylinder of the segment's depth and breadth with a
bone core of ``bone_depth_ratio`` of the depth (the source is recorded).

Passive joint springs are monotone moment-angle curves (:class:`JointSpring`),
built from sampled points with a shape-preserving PCHIP interpolant and
continued linearly outside the samples.

Units: lengths in m inside the model (mm at the interfaces named ``*_mm``),
masses kg, moments N m, angles deg at the interfaces and rad inside energies.

Over 400 lines: the finger's geometry, masses, joint springs and gravity use one frame and one set of segment definitions; the FEA check builds its mesh from the same ones.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd
from scipy.interpolate import PchipInterpolator
from scipy.optimize import root

from workflow.common.constants import JOINTS, SEGMENTS

__all__ = [
    "DIMENSIONS",
    "G_STANDARD",
    "Monotone1D",
    "JointSpring",
    "Segment",
    "Finger",
    "patient_dimensions_mm",
    "build_finger",
    "gravity_moments_nm",
    "gravity_droop_deg",
    "springs_from_loads",
]

DIMENSIONS = {"depth": "D", "length": "L", "breadth": "B"}
G_STANDARD = 9.81  # m/s^2, the paper's value (section 3.2)

# Stations of the section-point file, in the order of its point triplets
# (centre line, dorsal, palmar); the reading is the data README's.
_STATIONS = ("MC", "MCP", "PIP", "DIP", "NEAR_TIP")


# --------------------------------------------------------------------------
# Monotone 1D curves with linear continuation
# --------------------------------------------------------------------------
class Monotone1D:
    """Shape-preserving curve y(x) with linear continuation and its integral.

    Inside the samples a PCHIP interpolant (monotone data stay monotone);
    outside, straight lines with the slope of the nearest sample interval
    (secant, so a two-point curve is exactly linear and the continuation keeps
    the sign of the data's slope).

    Parameters
    ----------
    x, y : samples, ``x`` strictly increasing after sorting (duplicates in
        ``x`` are averaged).
    """

    def __init__(self, x: Sequence[float], y: Sequence[float]):
        x = np.asarray(x, float)
        y = np.asarray(y, float)
        ok = np.isfinite(x) & np.isfinite(y)
        x, y = x[ok], y[ok]
        xu, inv = np.unique(x, return_inverse=True)
        yu = np.bincount(inv, weights=y) / np.bincount(inv)
        if xu.size < 2:
            raise ValueError("a curve needs at least two distinct sample points")
        self.x = xu
        self.y = yu
        self._p = PchipInterpolator(xu, yu, extrapolate=False)
        self._P = self._p.antiderivative()
        self.slope_lo = (yu[1] - yu[0]) / (xu[1] - xu[0])
        self.slope_hi = (yu[-1] - yu[-2]) / (xu[-1] - xu[-2])

    def __call__(self, x):
        x = np.asarray(x, float)
        lo, hi = self.x[0], self.x[-1]
        xin = np.clip(x, lo, hi)
        out = np.asarray(self._p(xin), float)
        out = np.where(x < lo, self.y[0] + self.slope_lo * (x - lo), out)
        out = np.where(x > hi, self.y[-1] + self.slope_hi * (x - hi), out)
        return out

    def derivative(self, x):
        x = np.asarray(x, float)
        lo, hi = self.x[0], self.x[-1]
        d = np.asarray(self._p.derivative()(np.clip(x, lo, hi)), float)
        d = np.where(x < lo, self.slope_lo, d)
        return np.where(x > hi, self.slope_hi, d)

    def integral(self, a, b):
        """Integral of the curve from ``a`` to ``b`` (vectorised)."""
        return self._antider(np.asarray(b, float)) - self._antider(np.asarray(a, float))

    def _antider(self, x):
        lo, hi = self.x[0], self.x[-1]
        xin = np.clip(x, lo, hi)
        out = np.asarray(self._P(xin), float)  # zero at lo
        dlo = np.minimum(x - lo, 0.0)
        out = out + self.y[0] * dlo + 0.5 * self.slope_lo * dlo**2
        dhi = np.maximum(x - hi, 0.0)
        return out + self.y[-1] * dhi + 0.5 * self.slope_hi * dhi**2


@dataclass(frozen=True)
class JointSpring:
    """Passive torsional spring of one joint: moment (N m) against angle (deg).

    ``moment_nm(angle)`` is the flexion moment a device must apply to hold the
    joint at ``angle``, i.e. the spring's restoring moment.
    It is zero at 0 deg by definition and must not decrease with the angle.
    """

    curve: Monotone1D

    @classmethod
    def from_points(
        cls, angles_deg: Sequence[float], moments_nm: Sequence[float], add_origin: bool = True
    ) -> "JointSpring":
        """Spring through sampled (angle, moment) points, plus (0, 0) by default.

        Raises ``ValueError`` if the points are not monotone (non-decreasing)
        in the angle: a passive joint does not push back less when flexed more.
        """
        a = np.asarray(angles_deg, float)
        m = np.asarray(moments_nm, float)
        ok = np.isfinite(a) & np.isfinite(m)
        a, m = a[ok], m[ok]
        if add_origin:
            keep = np.abs(a) > 1e-12
            a = np.concatenate([[0.0], a[keep]])
            m = np.concatenate([[0.0], m[keep]])
        order = np.argsort(a)
        if np.any(np.diff(m[order]) < -1e-12):
            raise ValueError(f"passive moments are not monotone in the angle: {dict(zip(a, m))}")
        return cls(Monotone1D(a, m))

    @classmethod
    def linear(cls, stiffness_nm_per_deg: float) -> "JointSpring":
        """A linear spring (used by tests and as a documented fallback)."""
        return cls(Monotone1D([0.0, 1.0], [0.0, stiffness_nm_per_deg]))

    def moment_nm(self, angle_deg):
        return self.curve(angle_deg)

    def stiffness_nm_per_deg(self, angle_deg):
        return self.curve.derivative(angle_deg)

    def energy_j(self, angle_deg):
        """Stored energy (J) from 0 to ``angle_deg``: integral of M over rad."""
        return np.deg2rad(1.0) * self.curve.integral(0.0, angle_deg)


# --------------------------------------------------------------------------
# Geometry and masses
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class Segment:
    """One rigid phalanx.  Lengths m, mass kg.

    ``com_ref`` is the centre of mass in the reference (straight) pose, in the
    finger frame (x from the MCP centre, y dorsal).
    """

    name: str
    length_m: float
    mass_kg: float
    com_ref: tuple[float, float]
    depth_m: float
    breadth_m: float


@dataclass(frozen=True)
class Finger:
    """Three rigid phalanges hinged at MCP, PIP, DIP with torsional springs.

    ``joints_ref`` (3, 2): joint centres in the straight reference pose (m);
    ``dorsal_y_m``: height of the flat dorsal line the actuator rests on;
    ``tip_x_m``: x of the fingertip in the reference pose.
    """

    segments: tuple[Segment, Segment, Segment]
    springs: tuple[JointSpring, JointSpring, JointSpring]
    joints_ref: np.ndarray
    dorsal_y_m: float
    tip_x_m: float
    gravity_m_s2: float = G_STANDARD
    mass_source: str = ""
    dimensions_mm: Mapping[str, float] = field(default_factory=dict)

    @property
    def masses_kg(self) -> np.ndarray:
        return np.array([s.mass_kg for s in self.segments])

    @property
    def coms_ref(self) -> np.ndarray:
        return np.array([s.com_ref for s in self.segments])

    def pose(self, angles_deg: Sequence[float], points_ref: np.ndarray, segment_of: np.ndarray) -> np.ndarray:
        """Positions (m) of material points given in the reference pose.

        ``points_ref`` (n, 2); ``segment_of`` (n,) in {-1 (hand), 0, 1, 2}.
        """
        joints, phi = self.joint_positions(angles_deg)
        pts = np.asarray(points_ref, float)
        seg = np.asarray(segment_of, int)
        out = pts.copy()
        for k in range(3):
            sel = seg == k
            if np.any(sel):
                c, s = np.cos(phi[k]), np.sin(phi[k])
                d = pts[sel] - self.joints_ref[k]
                out[sel] = joints[k] + np.column_stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]])
        return out

    def joint_positions(self, angles_deg: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """Joint centres (3, 2) in m and segment rotations (3,) in rad (ccw)."""
        th = np.deg2rad(np.asarray(angles_deg, float))
        phi = -np.cumsum(th)
        joints = np.zeros((3, 2))
        joints[0] = self.joints_ref[0]
        for k in (1, 2):
            c, s = np.cos(phi[k - 1]), np.sin(phi[k - 1])
            d = self.joints_ref[k] - self.joints_ref[k - 1]
            joints[k] = joints[k - 1] + [c * d[0] - s * d[1], s * d[0] + c * d[1]]
        return joints, phi

    def outline(self, angles_deg: Sequence[float]) -> list[np.ndarray]:
        """Closed polygons (m) of the three segments, for plots."""
        out = []
        ends = [self.joints_ref[1, 0], self.joints_ref[2, 0], self.tip_x_m]
        for k, seg in enumerate(self.segments):
            x0, x1 = self.joints_ref[k, 0], ends[k]
            y_top = self.dorsal_y_m
            y_bot = y_top - seg.depth_m
            poly = np.array([[x0, y_top], [x1, y_top], [x1, y_bot], [x0, y_bot], [x0, y_top]])
            out.append(self.pose(angles_deg, poly, np.full(len(poly), k)))
        return out


def patient_dimensions_mm(
    measures: Mapping[str, Mapping[str, float]],
    coded: Mapping[str, float],
    coded_unit_sd: float = 1.0,
    measurements_mm: Mapping[str, float] | None = None,
) -> dict[str, float]:
    """Every Table 2 measure of a patient, mm.

    ``mean + coded[dim] * coded_unit_sd * sd`` per code (one
    coded unit is one SD of each matching measure), with measured values, where
    given, taking precedence.  ``coded`` maps ``depth``/``length``/``breadth``
    to coded levels.
    """
    prefix_dim = {v: k for k, v in DIMENSIONS.items()}
    out: dict[str, float] = {}
    for code, ms in measures.items():
        dim = prefix_dim[code[0]]
        out[code] = float(ms["mean"]) + float(coded.get(dim, 0.0)) * coded_unit_sd * float(ms["sd"])
    for code, v in (measurements_mm or {}).items():
        out[code] = float(v)
    return out


def _read_section_profile(path: Path) -> dict[str, object]:
    """Dorsal/palmar outline and bone profiles along the mean finger (mm).

    Returns station positions ``s`` (mm from the MCP centre towards the tip),
    the joint-centre heights, and profile points (s, z) for the outline and
    the bone, dorsal and palmar.
    """
    df = pd.read_csv(path)
    out: dict[str, object] = {}
    y_mcp = None
    for kind in ("outline", "bone"):
        d = df[df["kind"] == kind].sort_values("index")
        y = d["y_m"].to_numpy() * 1e3
        z = d["z_m"].to_numpy() * 1e3
        if len(y) < 17:
            raise ValueError(f"{path}: expected 17 {kind} points, found {len(y)}")
        if y_mcp is None:
            y_mcp = y[3]
        s = y_mcp - y  # distance from the MCP station towards the tip
        trip = np.arange(15).reshape(5, 3)
        dorsal = [(s[i[1]], z[i[1]]) for i in trip]
        palmar = [(s[i[2]], z[i[2]]) for i in trip]
        # Point 15 closes the tip (dorsal and palmar meet); point 16 is a
        # palmar pad point between DIP and the near-tip station.
        dorsal.append((s[15], z[15]))
        palmar += [(s[15], z[15]), (s[16], z[16])]
        out[kind] = {
            "dorsal": np.array(sorted(dorsal)),
            "palmar": np.array(sorted(palmar)),
            "centre": np.array([(s[i[0]], z[i[0]]) for i in trip]),
        }
    o = out["outline"]
    st = o["centre"][:, 0]
    out["s_joint"] = {"MCP": st[1], "PIP": st[2], "DIP": st[3]}
    out["s_tip"] = float(o["dorsal"][-1, 0])
    dors = np.interp(st[1:4], o["dorsal"][:, 0], o["dorsal"][:, 1])
    out["joint_below_dorsal"] = dict(zip(JOINTS, dors - o["centre"][1:4, 1]))
    return out


def _profile_depths(prof: Mapping, kind: str, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    p = prof[kind]
    dors = np.interp(s, p["dorsal"][:, 0], p["dorsal"][:, 1])
    palm = np.interp(s, p["palmar"][:, 0], p["palmar"][:, 1])
    return dors, np.maximum(dors - palm, 0.0)


def build_finger(
    dims_mm: Mapping[str, float],
    springs: Sequence[JointSpring],
    densities: Mapping[str, float],
    *,
    gravity_m_s2: float = G_STANDARD,
    section_points: str | Path | None = None,
    reference_dims_mm: Mapping[str, float] | None = None,
    bone_depth_ratio: float = 0.5,
    n_slices: int = 200,
) -> Finger:
    """The patient's finger model.

    Parameters
    ----------
    dims_mm : Table 2 measures of the patient (mm), at least L3PP, L3MP, L3DP,
        D3MCP, D3PIP, D3DIP, D3PP, D3MP, D3DP, B3PP, B3PIP, B3MP, B3DIP, B3DP.
    springs : MCP, PIP, DIP passive springs.
    densities : kg/m^3, keys ``flesh_proximal`` (PP), ``flesh_middle`` (MP),
        ``flesh_distal`` (DP), ``bone``.
    section_points : the authors' section-point CSV (mean finger), scaled to
        the patient; if ``None`` or missing, elliptic cylinders.
    reference_dims_mm : Table 2 means the section points belong to (needed to
        scale them); defaults to the patient's own values (no scaling).
    bone_depth_ratio : bone depth / segment depth, only for the fallback.
    """
    L = np.array([dims_mm["L3PP"], dims_mm["L3MP"], dims_mm["L3DP"]])
    seg_depth = np.array([dims_mm["D3PP"], dims_mm["D3MP"], dims_mm["D3DP"]])
    joint_depth = np.array([dims_mm["D3MCP"], dims_mm["D3PIP"], dims_mm["D3DIP"]])
    rho_flesh = np.array([densities["flesh_proximal"], densities["flesh_middle"], densities["flesh_distal"]])
    rho_bone = float(densities["bone"])
    xj = np.concatenate([[0.0], np.cumsum(L)])  # MCP, PIP, DIP, tip (mm)
    # Breadth knots (mm): joints and segment middles, the patient's B3 codes.
    b_knots_s = [xj[0], xj[0] + L[0] / 2, xj[1], xj[1] + L[1] / 2, xj[2], xj[2] + L[2] / 2, xj[3]]
    b_knots = [
        dims_mm["B3PP"],
        dims_mm["B3PP"],
        dims_mm["B3PIP"],
        dims_mm["B3MP"],
        dims_mm["B3DIP"],
        dims_mm["B3DP"],
        dims_mm["B3DP"],
    ]

    path = Path(section_points) if section_points else None
    prof = _read_section_profile(path) if path is not None and path.exists() else None
    ref = dict(reference_dims_mm or dims_mm)
    segments = []
    if prof is not None:
        source = f"section points {path.name} scaled to the patient (elliptic sections)"
        jb = prof["joint_below_dorsal"]
        ref_joint_depth = np.array([ref["D3MCP"], ref["D3PIP"], ref["D3DIP"]])
        below = np.array([jb[j] for j in JOINTS]) * joint_depth / ref_joint_depth
        s_file = np.array([prof["s_joint"]["MCP"], prof["s_joint"]["PIP"], prof["s_joint"]["DIP"], prof["s_tip"]])
        ref_seg_depth = np.array([ref["D3PP"], ref["D3MP"], ref["D3DP"]])
    else:
        source = f"elliptic cylinders from depth and breadth (bone depth ratio {bone_depth_ratio})"
        below = joint_depth / 2.0
    dorsal_y = below[0]  # MCP centre at the origin
    joints_ref = np.column_stack([xj[:3], dorsal_y - below]) * 1e-3
    for k, name in enumerate(SEGMENTS):
        t = (np.arange(n_slices) + 0.5) / n_slices
        s = xj[k] + t * L[k]
        ds = L[k] / n_slices
        b = np.interp(s, b_knots_s, b_knots)
        if prof is not None:
            # Map the patient's segment onto the file's and scale depths.
            s_f = s_file[k] + t * (s_file[k + 1] - s_file[k])
            _, d_o = _profile_depths(prof, "outline", s_f)
            _, d_b = _profile_depths(prof, "bone", s_f)
            scale = seg_depth[k] / ref_seg_depth[k]
            d_o, d_b = d_o * scale, np.minimum(d_b * scale, d_o * scale)
        else:
            d_o = np.full_like(s, seg_depth[k])
            d_b = bone_depth_ratio * d_o
        with np.errstate(invalid="ignore", divide="ignore"):
            b_bone = np.where(d_o > 0, b * d_b / d_o, 0.0)  # bone breadth in the same ratio
        a_o = np.pi / 4 * d_o * b  # mm^2
        a_b = np.pi / 4 * d_b * b_bone
        dm = (rho_flesh[k] * (a_o - a_b) + rho_bone * a_b) * ds * 1e-9  # kg per slice
        mass = float(dm.sum())
        x_com = float((dm * s).sum() / mass)
        y_com = float((dm * (dorsal_y - d_o / 2)).sum() / mass)  # section centroid below the dorsal line
        segments.append(
            Segment(
                name,
                L[k] * 1e-3,
                mass,
                (x_com * 1e-3, y_com * 1e-3),
                float(seg_depth[k]) * 1e-3,
                float(np.mean(b)) * 1e-3,
            )
        )
    return Finger(
        segments=tuple(segments),
        springs=tuple(springs),
        joints_ref=joints_ref,
        dorsal_y_m=float(dorsal_y) * 1e-3,
        tip_x_m=float(xj[3]) * 1e-3,
        gravity_m_s2=float(gravity_m_s2),
        mass_source=source,
        dimensions_mm=dict(dims_mm),
    )


def gravity_moments_nm(finger: Finger, angles_deg: Sequence[float]) -> np.ndarray:
    """Flexion moment (N m) of the segments' weights about each joint."""
    joints, _ = finger.joint_positions(angles_deg)
    com = finger.pose(angles_deg, finger.coms_ref, np.arange(3))
    w = finger.masses_kg * finger.gravity_m_s2
    out = np.zeros(3)
    for j in range(3):
        # A downward force F_y = -w at lever x: clockwise (flexion) moment w * x.
        out[j] = np.sum(w[j:] * (com[j:, 0] - joints[j, 0]))
    return out


def gravity_droop_deg(finger: Finger, x0: Sequence[float] | None = None) -> tuple[np.ndarray, bool]:
    """Joint angles (deg) where the springs hold the finger's own weight.

    Solves spring(theta_j) = gravity moment about j for all three joints
    (``scipy.optimize.root``).  Returns the angles and whether it converged.
    """

    def resid(th):
        return np.array([sp.moment_nm(t) for sp, t in zip(finger.springs, th)]) - gravity_moments_nm(finger, th)

    sol = root(resid, np.zeros(3) if x0 is None else np.asarray(x0, float), method="hybr", tol=1e-12)
    return np.asarray(sol.x), bool(sol.success)


def springs_from_loads(
    target_angle_deg: np.ndarray,
    passive_moment_nm: np.ndarray,
    curve_angle_deg: np.ndarray | None = None,
    curve_moment_nm: np.ndarray | None = None,
) -> tuple[list[JointSpring], str]:
    """The patient's three passive springs from the musculoskeletal stage.

    Parameters
    ----------
    target_angle_deg, passive_moment_nm : (exercise, joint) arrays of
        ``joint_loads.nc``: the patient's passive moment at each target angle.
    curve_angle_deg, curve_moment_nm : optional full passive curve per joint
        at the design centre, ``(angle,)`` and ``(joint, angle)`` (NaN where not
        sampled), e.g. ``moments.nc`` of the OpenSim backend.  A joint with at
        least three samples above 0 deg takes that curve's shape, scaled so it
        passes through the patient's moment at the joint's largest target angle
        ("scaled to the patient"); otherwise the patient's points alone.

    Returns the springs (MCP, PIP, DIP) and a note of the source per joint.
    """
    springs, notes = [], []
    for j, joint in enumerate(JOINTS):
        a = np.asarray(target_angle_deg, float)[:, j]
        m = np.asarray(passive_moment_nm, float)[:, j]
        ok = np.isfinite(a) & np.isfinite(m) & (a > 0)
        a, m = a[ok], m[ok]
        used = False
        if curve_angle_deg is not None and curve_moment_nm is not None and a.size:
            ca = np.asarray(curve_angle_deg, float)
            cm = np.asarray(curve_moment_nm, float)[j]
            sel = np.isfinite(cm) & (ca > 0)
            # The sampled moment at 0 deg can be non-zero (muscle tone of the
            # passive activation); the spring is zero at 0 deg by definition
            # (the moment at a 0-deg target), so the curve is taken relative to it.
            at0 = np.isfinite(cm) & (np.abs(ca) < 1e-9)
            cm0 = float(cm[at0][0]) if at0.any() else 0.0
            if np.count_nonzero(sel) >= 3:
                k = int(np.argmax(a))
                ref = float(np.interp(a[k], ca[sel], cm[sel]))
                if ref > 0:
                    springs.append(JointSpring.from_points(ca[sel], (cm[sel] - cm0) * m[k] / ref))
                    notes.append(f"{joint}: curve shape scaled to the patient at {a[k]:g} deg")
                    used = True
        if not used:
            if a.size == 0:
                raise ValueError(f"no passive moment above 0 deg for {joint}: cannot build its spring")
            springs.append(JointSpring.from_points(a, m))
            notes.append(f"{joint}: patient points at {sorted(set(a.tolist()))} deg and 0")
    return springs, "; ".join(notes)
