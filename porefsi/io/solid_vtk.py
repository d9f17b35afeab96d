"""ParaView-readable ``.vtu`` files of the solid tetrahedral mesh (via meshio).

Point arrays (Nn, ...) and cell arrays (Ne, ...) travel as VTK data arrays; float64 values
round-trip exactly (binary appended encoding). Inputs are never modified.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from porefsi.errors import InputError
from porefsi.io.results import atomic_path

__all__ = ["write_solid_vtu", "read_solid_vtu"]


def write_solid_vtu(path: str | Path, points: np.ndarray, tets: np.ndarray, *,
                    point_data: Mapping[str, np.ndarray] | None = None,
                    cell_data: Mapping[str, np.ndarray] | None = None) -> Path:
    """Write a tetrahedral mesh with data to ``path`` (``.vtu``).

    Parameters
    ----------
    path : str or Path
        Output file; the suffix must be ``.vtu``. Parent folders are created.
    points : ndarray, shape (Nn, 3)
        Node coordinates, m (pass ``points + u`` for the deformed configuration).
    tets : ndarray of int, shape (Ne, 4)
    point_data : mapping of name -> ndarray (Nn,) or (Nn, k), optional
    cell_data : mapping of name -> ndarray (Ne,) or (Ne, k), optional

    Returns
    -------
    Path
        The file written.

    Raises
    ------
    InputError
        Wrong suffix or array shapes.
    """
    import meshio

    path = Path(path)
    if path.suffix != ".vtu":
        raise InputError(f"solid meshes are written as .vtu, got {path.name!r}; use a .vtu suffix")
    pts = np.array(points, dtype=np.float64)
    cells = np.array(tets, dtype=np.int64)
    if pts.ndim != 2 or pts.shape[1] != 3 or cells.ndim != 2 or cells.shape[1] != 4:
        raise InputError(f"need points (Nn, 3) and tets (Ne, 4), got {pts.shape} and {cells.shape}")
    pd = {}
    for k, v in (point_data or {}).items():
        a = np.array(v, dtype=np.float64)
        if a.shape[0] != len(pts):
            raise InputError(f"point array {k!r} has {a.shape[0]} rows, mesh has {len(pts)} points")
        pd[str(k)] = a
    cd = {}
    for k, v in (cell_data or {}).items():
        a = np.array(v, dtype=np.float64)
        if a.shape[0] != len(cells):
            raise InputError(f"cell array {k!r} has {a.shape[0]} rows, mesh has {len(cells)} tets")
        cd[str(k)] = [a]
    with atomic_path(path) as tmp:  # atomic, with the umask's permissions
        meshio.Mesh(pts, [("tetra", cells)], point_data=pd, cell_data=cd).write(
            tmp, file_format="vtu", binary=True, compression=None)
    return path


def read_solid_vtu(path: str | Path):
    """Read a ``.vtu`` written by :func:`write_solid_vtu`: ``(points, tets, point_data, cell_data)``."""
    import meshio

    m = meshio.read(Path(path))
    tets = m.cells_dict.get("tetra")
    if tets is None:
        raise InputError(f"{path} holds no tetrahedra")
    cd = {k: v[0] for k, v in m.cell_data.items()}
    return m.points, tets, dict(m.point_data), cd
