"""Fits within a tolerance (``tolerance=``): greedy reduction of the data points."""

from __future__ import annotations

import pickle
import warnings

import numpy as np
import pytest

import implicitmesh as im
from implicitmesh import VariationalSurface, shapes


@pytest.fixture(scope="module")
def sphere_points():
    return shapes.fibonacci_sphere(6000)


def test_fit_within_tolerance_uses_fewer_points_and_meets_it(sphere_points):
    p, n = sphere_points
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "outside the tolerance" warning
        s = VariationalSurface.fit(p, n, tolerance=1e-4, exact=True)
    r = s.reduction
    assert r["outside"] == 0 and 1 <= r["rounds"] <= 4
    assert r["used"] < len(p) / 2
    residual = np.abs(s(p))
    assert residual.max() <= 1e-4
    assert r["largest_residual"] == pytest.approx(residual.max(), rel=1e-9, abs=1e-15)
    # The points used are interpolated: as many data points have |f| at rounding level.
    assert (residual < 1e-9).sum() >= r["used"]
    assert len(s) == 2 * r["used"]
    mesh = im.polygonize(s, resolution=48, method="octree", project=True)
    tm = mesh.to_trimesh()
    assert tm.is_watertight and len(tm.split(only_watertight=False)) == 1
    assert np.abs(np.linalg.norm(mesh.vertices, axis=1) - 0.8).max() < 1e-3


def test_exact_fits_and_loaded_surfaces_have_no_reduction(sphere_points):
    p, n = sphere_points
    s = VariationalSurface.fit(p[:500], n[:500], exact=True)
    assert s.reduction is None
    t = VariationalSurface.fit(p, n, tolerance=1e-3, exact=True)
    assert t.reduction is not None
    u = pickle.loads(pickle.dumps(t))
    assert u.reduction is None
    np.testing.assert_array_equal(u(p[:100]), t(p[:100]))


def test_interpolate_within_tolerance():
    rng = np.random.default_rng(3)
    x = rng.uniform(-1, 1, (4000, 3))
    v = np.sin(2 * x[:, 0]) * np.cos(x[:, 1]) + 0.5 * x[:, 2] ** 2
    s = VariationalSurface.interpolate(x, v, tolerance=1e-3)
    assert s.reduction["outside"] == 0 and s.reduction["used"] < len(x)
    assert np.abs(s(x) - v).max() <= 1e-3


def test_a_tolerance_out_of_reach_warns_and_reports():
    """A tolerance below rounding: the second fit takes every point, and rounding leaves some
    outside."""
    p, n = shapes.fibonacci_sphere(1500)
    noisy = p + np.random.default_rng(0).normal(scale=2e-3, size=p.shape)
    with pytest.warns(UserWarning, match="farther than tolerance"):
        s = VariationalSurface.fit(noisy, n, tolerance=1e-15, method="global", exact=True)
    r = s.reduction
    assert r["rounds"] == 2 and r["used"] == len(p)
    assert r["outside"] > 0 and r["largest_residual"] > 1e-15


@pytest.mark.parametrize("bad", [0.0, -1e-3, float("nan"), float("inf")])
def test_bad_tolerance_is_refused_by_name(sphere_points, bad):
    p, n = sphere_points
    with pytest.raises(ValueError, match="tolerance"):
        VariationalSurface.fit(p, n, tolerance=bad, exact=True)
