"""The measuring tools of the speed-accuracy and coupling-stability studies (cases/*/run.py).

The studies' conclusions rest on three small functions: the Pareto filter, the space-time
interpolation that puts a run's displacement on the reference's evaluation points, and the
contraction-factor estimate of a sub-iteration history. Each is checked here on inputs with a
known answer (no coupled run: < 1 s).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

CASES = Path(__file__).resolve().parents[1] / "cases"


def _load(name: str):
    spec = importlib.util.spec_from_file_location(f"case_{name}", CASES / name / "run.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def sa():
    return _load("speed_accuracy")


@pytest.fixture(scope="module")
def stab():
    return _load("coupling_stability")


def test_pareto_removes_dominated_and_keeps_ties(sa):
    # (cost, err): B is dominated by A (cheaper and more accurate); C is the accurate end;
    # D equals A within the tolerances (0.5 % error, 5 % time): a tie, not dominated.
    cost = [1.0, 2.0, 10.0, 1.05]
    err = [0.10, 0.20, 0.01, 0.1005]
    assert sa.pareto(cost, err).tolist() == [True, False, True, True]
    # without tolerance, A strictly dominates D
    assert sa.pareto(cost, err, tol_err=0.0, tol_time=0.0).tolist() == [True, False, True, False]


def test_pareto_front_is_monotone_on_random_clouds(sa, rng):
    # Along the front sorted by cost the error must not increase (beyond the tolerance).
    for _ in range(5):
        c = 10 ** rng.uniform(0, 3, 40)
        e = 10 ** rng.uniform(-3, 0, 40)
        m = sa.pareto(c, e, tol_err=0.0, tol_time=0.0)
        order = np.argsort(c[m])
        assert np.all(np.diff(e[m][order]) <= 0)
        # every removed point is dominated by some front point
        for b in np.flatnonzero(~m):
            assert np.any((c[m] <= c[b]) & (e[m] <= e[b]))


def test_space_time_interpolation_exact_for_affine_fields(sa, rng):
    # Nodes of a voxel mesh sit on a grid; trilinear interpolation reproduces an affine field
    # exactly, and linear time interpolation reproduces a field linear in t.
    spacing, shape = 2.0, (5, 4, 6)
    ijk = np.stack(np.meshgrid(*[np.arange(s) for s in shape], indexing="ij"), -1).reshape(-1, 3)
    ijk = ijk[rng.random(len(ijk)) < 0.8]  # some corners missing (pores) ...
    ijk = np.unique(np.vstack([ijk, [[0, 0, 0], [4, 3, 5], [4, 0, 0], [0, 3, 0], [0, 0, 5]]]), axis=0)
    pts = ijk * spacing
    A, b = rng.normal(size=(3, 3)), rng.normal(size=3)
    res = {"points": pts, "spacing": spacing, "gshape": shape, "origin": np.zeros(3), "times": np.array([0.0, 2.0]),
           "U": [np.zeros_like(pts), pts @ A.T + b]}
    X = pts[rng.choice(len(pts), 10)]  # evaluation at nodes: exact whatever the fill
    np.testing.assert_allclose(sa.on_points(res, sa.at_time(res, 0.5), X), 0.25 * (X @ A.T + b), rtol=1e-12,
                               atol=1e-12)
    with pytest.raises(ValueError):
        sa.at_time(res, 3.0)


def test_rel_l2(sa):
    r = [np.ones((4, 3)), 2 * np.ones((2, 3))]
    e = [0.1 * x for x in r]
    assert sa.rel_l2(e, r) == pytest.approx(0.1)


def test_contraction_factor_of_geometric_sequence(stab):
    h = np.r_[1.0, 0.3 * 0.4 ** np.arange(30)]
    assert stab.contraction(h) == pytest.approx(0.4, rel=1e-12)
    # a history that drops straight to the round-off floor has no measurable ratio
    assert stab.contraction(np.array([1.0, 1e-14, 1e-15])) is None
