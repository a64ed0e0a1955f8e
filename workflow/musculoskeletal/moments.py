"""The shared layout of joint-moment samples (``moments.nc``) and response names.

``moment_nm`` (run, finger, joint, angle_deg, activation) is the flexion moment,
N m, that an external device must apply to hold the joint at ``angle_deg`` with
the other joints of the finger at 0 deg.  A *response* is one
(finger, activation, joint, angle) cell, named as in the authors' export:
``F3_P_MCP_90`` = middle finger, passive (activation 0.01), MCP at 90 deg.
"""

from __future__ import annotations

import re
from typing import Iterable, Mapping

import numpy as np
import xarray as xr

from ..common.constants import JOINTS

__all__ = [
    "FINGERS",
    "ACTIVATIONS",
    "RESPONSE_RE",
    "response_name",
    "parse_response",
    "empty_moments",
    "response_angles",
    "responses_from_moments",
]

FINGERS = ("F2", "F3", "F4", "F5")
ACTIVATIONS = {"P": 0.01, "A": 1.0}
RESPONSE_RE = re.compile(r"^(F[2-5])_([PA])_(MCP|PIP|DIP)_(-?\d+(?:\.\d+)?)$")


def response_name(finger: str, activation: float, joint: str, angle_deg: float) -> str:
    kind = "P" if activation < 0.5 else "A"
    return f"{finger}_{kind}_{joint}_{angle_deg:g}"


def parse_response(name: str) -> tuple[str, float, str, float]:
    """``F3_P_MCP_90`` -> (``F3``, 0.01, ``MCP``, 90.0)."""
    m = RESPONSE_RE.match(name)
    if not m:
        raise ValueError(f"not a response name: {name!r} (expected e.g. F3_P_MCP_90)")
    finger, kind, joint, angle = m.groups()
    return finger, ACTIVATIONS[kind], joint, float(angle)


def empty_moments(runs: Iterable[int], angles_deg: Iterable[float], fingers=FINGERS) -> xr.Dataset:
    """An all-NaN ``moments.nc`` dataset to be filled by a backend."""
    runs = list(runs)
    angles = sorted(set(float(a) for a in angles_deg))
    shape = (len(runs), len(fingers), len(JOINTS), len(angles), len(ACTIVATIONS))
    ds = xr.Dataset(
        {"moment_nm": (("run", "finger", "joint", "angle_deg", "activation"), np.full(shape, np.nan))},
        coords={
            "run": runs,
            "finger": list(fingers),
            "joint": list(JOINTS),
            "angle_deg": angles,
            "activation": list(ACTIVATIONS.values()),
        },
    )
    ds["moment_nm"].attrs = {
        "units": "N m",
        "long_name": "flexion moment an external device applies to hold the joint (other joints at 0 deg)",
    }
    ds["angle_deg"].attrs = {"units": "degree", "long_name": "joint flexion angle"}
    ds["activation"].attrs = {"units": "1", "long_name": "muscle activation (0.01 passive, 1 active)"}
    return ds


def response_angles(exercises: Mapping[str, Mapping[str, float]]) -> dict[str, dict[str, list[float]]]:
    """Angles at which responses are fitted, per activation kind and joint.

    Passive: every nonzero target angle of the exercises (at 0 deg the passive
    moment is 0 by definition).  Active: the joint's largest target angle, where
    the safety limit is read.
    """
    out: dict[str, dict[str, list[float]]] = {"P": {}, "A": {}}
    for joint in JOINTS:
        angles = sorted({float(ex[joint.lower()]) for ex in exercises.values()})
        out["P"][joint] = [a for a in angles if a != 0]
        out["A"][joint] = [max(angles)] if angles and max(angles) > 0 else []
    return out


def responses_from_moments(moments: xr.Dataset, exercises: Mapping) -> dict[str, np.ndarray]:
    """Response columns (name -> values over ``run``) for the RSM stage.

    Only responses with data at every run are returned.
    """
    want = response_angles(exercises)
    out: dict[str, np.ndarray] = {}
    for finger in moments["finger"].values:
        for kind, act in ACTIVATIONS.items():
            for joint, angles in want[kind].items():
                for angle in angles:
                    if angle not in moments["angle_deg"].values:
                        continue
                    y = moments["moment_nm"].sel(finger=finger, activation=act, joint=joint, angle_deg=angle).values
                    if np.all(np.isfinite(y)):
                        out[response_name(str(finger), act, joint, angle)] = y
    return out
