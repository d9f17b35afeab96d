"""Numba kernels of the maximal-ball extraction, gathered for :mod:`porefsi.network.extract`.

The kernels live in one module per concept (kept under ~500 lines each):

* :mod:`porefsi.network._mb_edt`: squared Euclidean distance transform, pore-solid faces;
* :mod:`porefsi.network._mb_balls`: maximal balls and the master/slave hierarchy;
* :mod:`porefsi.network._mb_regions`: voxel regions (flood), interfaces (throats), pore stats.

Every kernel takes arrays and scalars only and has a slow pure-Python twin in
``tests/reference/extract_ref.py``. Integer voxel coordinates: voxel ``(i, j, k)`` has centre
``(i, j, k)``; the public wrapper adds the half voxel and the origin.
"""

from porefsi.network._mb_balls import _families, _fill, _isqrt, _maximal_balls, ball_offsets, ball_reach_table
from porefsi.network._mb_edt import CAP16, INF, _envelope_line, _pore_solid_faces, _sq_edt
from porefsi.network._mb_regions import _flood, _interfaces, _pore_stats, _relabel

__all__ = [
    "CAP16",
    "INF",
    "_envelope_line",
    "_families",
    "_fill",
    "_flood",
    "_interfaces",
    "_isqrt",
    "_maximal_balls",
    "_pore_solid_faces",
    "_pore_stats",
    "_relabel",
    "_sq_edt",
    "ball_offsets",
    "ball_reach_table",
]
