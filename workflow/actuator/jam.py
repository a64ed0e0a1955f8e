"""A unit inside a long actuator: its bend capped where neighbouring blocks jam.

The unit model (:mod:`.unit_model`) comes from three chambers, two of them end units whose blocks splay outwards.
Inside a long actuator a unit's unpressurised blocks on the concave side meet their neighbours at the jam angle
``J`` (gap over the corners' distance from the paper's mid-plane, :func:`workflow.fem.actuator.jam_angle_deg`;
3.35 deg for Table 6), and past it the unit bends only as far as those blocks squeeze.  The 2D whole actuator of
thirteen units (docs/actuator.md, "A unit inside a long actuator") gives, for its interior units,

    theta_interior = J + s (theta_unit - J)    where theta_unit > J,     s = 0.07-0.12 (20-75 kPa),

and the unit model's own bend below J; mirrored for extension (the section is symmetric about the paper).  Near the
actuator's free end the bend returns to the unit model's over a boundary layer that decays by about 0.6 per unit
(a decay length of two units): the unit k places before the last two bends ``theta_c + exp(-k / decay) (theta_unit -
theta_c)``, ``theta_c`` the capped bend, and the last two units the unit model's bend.  On the finger the straps hold the distal units and
the finger-actuator FEA is matched better without that layer (the chain's default, ``decay_units = 0``).

Pure functions, vectorised; angles deg.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workflow.fem.actuator import jam_angle_deg

__all__ = ["JamModel", "capped_bend_deg", "capped_bend_slope", "free_end_weights"]


def _softplus(x: np.ndarray) -> np.ndarray:
    return np.logaddexp(0.0, x)


def capped_bend_deg(theta_deg, jam_deg: float, slope: float, width_deg: float = 0.2) -> np.ndarray:
    """The bend of an interior unit whose unit-model bend is ``theta_deg`` (deg): itself below the jam angle
    ``jam_deg``, ``jam + slope (theta - jam)`` past it, odd in theta; the corner rounded over about ``width_deg``
    so that the chain's root finders see a smooth function (C-infinity; off by at most 0.7 ``width_deg``
    (1 - slope) from the sharp cap, at the corner)."""
    th = np.asarray(theta_deg, float)
    w = float(width_deg)
    k = (1.0 - float(slope)) * w
    return th - k * (_softplus((th - jam_deg) / w) - _softplus((-th - jam_deg) / w))


def free_end_weights(n_units: int, decay_units: float) -> np.ndarray:
    """Weight of the unit model's bend over the capped one for each of ``n_units`` units, hand end first (n,):
    ``exp(-k / decay_units)`` with k the unit's place from the free end, the last two alike (k = 0); 0 everywhere
    for ``decay_units`` <= 0."""
    n = int(n_units)
    if decay_units <= 0:
        return np.zeros(n)
    k = np.maximum(np.arange(n)[::-1] - 1, 0)
    return np.exp(-k / float(decay_units))


def capped_bend_slope(theta_deg, jam_deg: float, slope: float, width_deg: float = 0.2) -> np.ndarray:
    """d :func:`capped_bend_deg` / d theta (1): 1 below the jam angle, ``slope`` past it."""
    th = np.asarray(theta_deg, float)
    w = float(width_deg)
    sig = 0.5 * (1.0 + np.tanh(0.5 * (th - jam_deg) / w)) + 0.5 * (1.0 + np.tanh(0.5 * (-th - jam_deg) / w))
    return 1.0 - (1.0 - float(slope)) * sig


@dataclass(frozen=True)
class JamModel:
    """The jam of a unit inside the actuator: angle (deg), slope past it (1), the free end's decay (units)."""

    jam_deg: float
    slope: float = 0.1
    decay_units: float = 0.0  # 2 for the actuator alone; on the finger the straps hold the distal units
    width_deg: float = 0.2

    def __post_init__(self):
        # a zero slope would make the capped bend flat past the jam: no unique inverse, an infinite stiffness
        if not (self.jam_deg > 0 and 0.0 < self.slope <= 1.0 and self.width_deg > 0):
            raise ValueError(f"jam model: need jam > 0 deg, 0 < slope <= 1, width > 0; got {self}")

    @classmethod
    def from_geometry(cls, geometry_mm, **kwargs) -> "JamModel":
        """The jam of the unit with Table 6's dimensions ``geometry_mm`` (gap, height, bot_layer, paper_width)."""
        return cls(jam_angle_deg(geometry_mm), **kwargs)

    def bend_deg(self, theta_deg, end_weight) -> np.ndarray:
        """Bend (deg) of a unit with unit-model bend ``theta_deg`` and free-end weight ``end_weight`` (0 inside,
        1 at the free end; broadcast)."""
        th = np.asarray(theta_deg, float)
        tc = capped_bend_deg(th, self.jam_deg, self.slope, self.width_deg)
        return tc + np.asarray(end_weight, float) * (th - tc)

    def bend_slope(self, theta_deg, end_weight) -> np.ndarray:
        """d :meth:`bend_deg` / d theta (1): how much of a change of the unit model's bend the unit follows (its
        compliance to a moment is the unit model's times this)."""
        c = capped_bend_slope(theta_deg, self.jam_deg, self.slope, self.width_deg)
        return c + np.asarray(end_weight, float) * (1.0 - c)
