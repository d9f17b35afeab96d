"""Naive twins of the coupling kernels: brute force over every node, plane and test point."""

import numpy as np
from scipy.spatial import ConvexHull


def hull_members_ref(points, centres, radii, test_points, test_ptr, tolerance):
    members = []
    for i in range(len(centres)):
        eq = ConvexHull(test_points[test_ptr[i]:test_ptr[i + 1]]).equations
        vals = points @ eq[:, :3].T + eq[:, 3]
        inside = np.all(vals <= tolerance[i], axis=1)
        members.append(np.flatnonzero(inside))
    return members


def nearest_member_ref(test_points, test_ptr, member_ptr, member_nodes, points):
    out = np.full(len(test_points), -1)
    for i in range(len(test_ptr) - 1):
        m = np.arange(member_ptr[i], member_ptr[i + 1])
        if m.size == 0:
            continue
        for t in range(test_ptr[i], test_ptr[i + 1]):
            d = np.linalg.norm(points[member_nodes[m]] - test_points[t], axis=1)
            out[t] = m[np.argmin(d)]
    return out
