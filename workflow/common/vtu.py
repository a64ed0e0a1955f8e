"""The one .vtu writer: an FE mesh with its displacement field, for ParaView.

Units as the mesh (mm); the displacement is written as point data padded to
three components; ``deform`` moves the points by it (the deformed shape) and
``cell_data`` adds per-cell integer fields (material, body).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import numpy as np

__all__ = ["write_vtu"]


def write_vtu(
    mesh: Any,
    u: np.ndarray,
    path: str | Path,
    *,
    deform: bool = False,
    cell_data: Mapping[str, np.ndarray] | None = None,
) -> Path:
    """Write the scikit-fem ``mesh`` with the nodal displacement ``u`` (DOFs node-major) to ``path``."""
    from skfem.io.meshio import to_meshio

    dim = mesh.p.shape[0]
    d = np.asarray(u, float).reshape(-1, dim)
    d3 = np.column_stack([d, np.zeros((len(d), 3 - dim))]) if dim < 3 else d
    m = to_meshio(mesh, point_data={"displacement": d3})
    if deform:
        p = mesh.p.T
        m.points = (np.column_stack([p, np.zeros((len(p), 3 - dim))]) if dim < 3 else p) + d3
    for k, v in (cell_data or {}).items():
        m.cell_data[k] = [np.asarray(v).astype(np.int32)]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    m.write(path)
    return path
