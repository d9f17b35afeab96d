"""numba kernels of the fluid-solid interface (private; validated wrappers in ``interface.py``)."""

from __future__ import annotations

import numpy as np

from porefsi._numba import jit


@jit
def _bin_points(points, lo, cell, dims):
    """Sort points into a uniform grid; return (order, cell_start) in CSR form."""
    n = points.shape[0]
    ncell = dims[0] * dims[1] * dims[2]
    cid = np.empty(n, np.int64)
    for p in range(n):
        c = np.empty(3, np.int64)
        for d in range(3):
            k = int((points[p, d] - lo[d]) / cell)
            if k < 0:
                k = 0
            elif k >= dims[d]:
                k = dims[d] - 1
            c[d] = k
        cid[p] = (c[0] * dims[1] + c[1]) * dims[2] + c[2]
    counts = np.zeros(ncell + 1, np.int64)
    for p in range(n):
        counts[cid[p] + 1] += 1
    for c in range(ncell):
        counts[c + 1] += counts[c]
    fill = counts[:-1].copy()
    order = np.empty(n, np.int64)
    for p in range(n):
        order[fill[cid[p]]] = p
        fill[cid[p]] += 1
    return order, counts


@jit
def _hull_members(grid, hulls, out_pore, out_node):
    """Points inside each enlarged hull ``n . x + d <= eps`` (all planes of that pore).

    ``grid = (points, order, start, lo, cell, dims)`` is the binned point cloud
    (:func:`_bin_points`), ``hulls = (centres, reach, planes, plane_ptr, eps)`` the pores' hulls.
    Candidate points come from the grid cells overlapping the ball ``|x - c| <= reach``.
    When ``out_pore`` is empty only counts are returned (first pass); otherwise it is filled.
    """
    points, order, start, lo, cell, dims = grid
    centres, reach, planes, plane_ptr, eps = hulls
    count = 0
    fill = out_pore.shape[0] > 0
    for i in range(centres.shape[0]):
        lo_c = np.empty(3, np.int64)
        hi_c = np.empty(3, np.int64)
        for d in range(3):
            a = int((centres[i, d] - reach[i] - lo[d]) / cell)
            b = int((centres[i, d] + reach[i] - lo[d]) / cell)
            lo_c[d] = min(max(a, 0), dims[d] - 1)
            hi_c[d] = min(max(b, 0), dims[d] - 1)
        r2 = reach[i] * reach[i]
        for cx in range(lo_c[0], hi_c[0] + 1):
            for cy in range(lo_c[1], hi_c[1] + 1):
                for cz in range(lo_c[2], hi_c[2] + 1):
                    c = (cx * dims[1] + cy) * dims[2] + cz
                    for s in range(start[c], start[c + 1]):
                        p = order[s]
                        dx = points[p, 0] - centres[i, 0]
                        dy = points[p, 1] - centres[i, 1]
                        dz = points[p, 2] - centres[i, 2]
                        if dx * dx + dy * dy + dz * dz > r2:
                            continue
                        inside = True
                        for f in range(plane_ptr[i], plane_ptr[i + 1]):
                            v = (planes[f, 0] * points[p, 0] + planes[f, 1] * points[p, 1]
                                 + planes[f, 2] * points[p, 2] + planes[f, 3])
                            if v > eps[i]:
                                inside = False
                                break
                        if inside:
                            if fill:
                                out_pore[count] = i
                                out_node[count] = p
                            count += 1
    return count


@jit
def _nearest_member(test_points, test_ptr, member_ptr, member_nodes, points):
    """For each test point of pore i, the index (into ``member_nodes``) of its nearest member node.

    Returns -1 for test points of pores with no member.
    """
    out = np.full(test_points.shape[0], -1, np.int64)
    for i in range(test_ptr.shape[0] - 1):
        m0 = member_ptr[i]
        m1 = member_ptr[i + 1]
        if m1 == m0:
            continue
        for t in range(test_ptr[i], test_ptr[i + 1]):
            best = np.inf
            arg = -1
            for m in range(m0, m1):
                p = member_nodes[m]
                dx = points[p, 0] - test_points[t, 0]
                dy = points[p, 1] - test_points[t, 1]
                dz = points[p, 2] - test_points[t, 2]
                d2 = dx * dx + dy * dy + dz * dz
                if d2 < best:
                    best = d2
                    arg = m
            out[t] = arg
    return out
