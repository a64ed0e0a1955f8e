"""Drucker stability of the silicone's Mooney-Rivlin constants (Table 5), checked before any FE job.

The law is the incompressible three-term Mooney-Rivlin form of the FE model
(paper section 3.1, Table 5)::

    psi = c10 (I1 - 3) + c01 (I2 - 3) + c20 (I1 - 3)^2

As commercial FE codes check a fit, each of the three homogeneous test modes
is loaded over a range of stretches (principal stretches, lateral faces free):

    uniaxial      (l, l^-1/2, l^-1/2)   sigma = 2 (l^2 - l^-1) (W1 + W2 / l)
    equibiaxial   (l, l, l^-2)          sigma = 2 (l^2 - l^-4) (W1 + l^2 W2)
    planar        (l, 1, l^-1)          sigma = 2 (l^2 - l^-2) (W1 + W2)

with W1 = dpsi/dI1 = c10 + 2 c20 (I1 - 3) and W2 = dpsi/dI2 = c01; sigma is
the Cauchy stress in the loaded direction (MPa) and sigma / l the nominal one.
The law is stable at a stretch where both increase with the stretch: Drucker's
d sigma : d eps > 0 along the mode (Cauchy stress against logarithmic strain),
and no limit point of the nominal stress.  Also required: an initial shear
modulus mu0 = 2 (c10 + c01) > 0.  No I/O here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MODES", "Instability", "mooney_rivlin_mode_stress", "drucker_instabilities"]

MODES = ("uniaxial", "equibiaxial", "planar")


@dataclass(frozen=True)
class Instability:
    """The stretch ranges (dimensionless, as sampled) of one mode where the law is not stable."""

    mode: str
    ranges: tuple[tuple[float, float], ...]  # (first, last) unstable stretch of each contiguous range
    stress: str  # "Cauchy" or "nominal": which stress stops increasing at the first unstable stretch
    within: bool  # any unstable stretch inside the required range

    def __str__(self) -> str:
        where = " and ".join(f"{a:.3g}" if a == b else f"{a:.3g}-{b:.3g}" for a, b in self.ranges)
        return f"{self.mode} mode unstable at stretch {where} ({self.stress} stress does not increase with the stretch)"


def mooney_rivlin_mode_stress(c10_mpa: float, c01_mpa: float, c20_mpa: float, stretch, mode: str):
    """(Cauchy, nominal) stress (MPa) in the loaded direction of ``mode`` at principal ``stretch`` (1)."""
    lam = np.asarray(stretch, float)
    if mode == "uniaxial":
        i1, fac, w2 = lam**2 + 2.0 / lam, lam**2 - 1.0 / lam, 1.0 / lam
    elif mode == "equibiaxial":
        i1, fac, w2 = 2.0 * lam**2 + lam**-4, lam**2 - lam**-4, lam**2
    elif mode == "planar":
        i1, fac, w2 = lam**2 + 1.0 + lam**-2, lam**2 - lam**-2, np.ones_like(lam)
    else:
        raise ValueError(f"unknown mode {mode!r}: expected one of {MODES}")
    sigma = 2.0 * fac * (c10_mpa + 2.0 * c20_mpa * (i1 - 3.0) + c01_mpa * w2)
    return sigma, sigma / lam


def drucker_instabilities(
    c10_mpa: float, c01_mpa: float, c20_mpa: float, *, span=(0.3, 3.0), required=(0.5, 2.0), n: int = 2701
) -> list[Instability]:
    """Per mode, the stretches in ``span`` where the law is unstable (empty list: stable throughout).

    ``within`` marks an instability that reaches into ``required`` (the
    stretches an FE model of the actuator may see); outside it, one that
    only a larger or smaller stretch would meet.
    """
    lam = np.linspace(span[0], span[1], n)
    h = 1e-6  # central differences: the stresses are smooth in the stretch
    out = []
    for mode in MODES:
        s_hi, p_hi = mooney_rivlin_mode_stress(c10_mpa, c01_mpa, c20_mpa, lam + h, mode)
        s_lo, p_lo = mooney_rivlin_mode_stress(c10_mpa, c01_mpa, c20_mpa, lam - h, mode)
        cauchy_bad, nominal_bad = s_hi - s_lo <= 0, p_hi - p_lo <= 0
        bad = cauchy_bad | nominal_bad
        if not bad.any():
            continue
        edges = np.flatnonzero(np.diff(np.concatenate([[0], bad.astype(int), [0]])))  # starts, ends + 1
        ranges = tuple((float(lam[a]), float(lam[b - 1])) for a, b in zip(edges[::2], edges[1::2]))
        inside = bad & (lam >= required[0]) & (lam <= required[1])
        out.append(Instability(mode, ranges, "Cauchy" if cauchy_bad[edges[0]] else "nominal", bool(inside.any())))
    return out
