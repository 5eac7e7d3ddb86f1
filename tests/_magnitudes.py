"""Coordinates over the whole finite range, thrown at every public entry point.

Run by ``tests/test_extreme.py``, one check per subprocess (``python -c "import _magnitudes;
_magnitudes.check_fits()"``), so that a crash or a hang fails that test instead of taking the
suite down. Each check is a hypothesis test: every call returns a result or raises
ValueError, TypeError or MemoryError, and the check prints ``ok`` at the end.
"""

from __future__ import annotations

import os
import pickle
import sys
import tempfile

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import implicitmesh as im
from implicitmesh import _core

#: Examples per check; the checks together stay within about a minute on two cores.
EXAMPLES = int(os.environ.get("IMPLICITMESH_MAGNITUDE_EXAMPLES", "60"))
CHECK = settings(max_examples=EXAMPLES, deadline=None, database=None, suppress_health_check=list(HealthCheck))
REFUSED = (ValueError, TypeError, MemoryError)

SCALES = [1e-300, 1e-150, 1e-20, 1e-3, 1.0, 1e3, 1e20, 1e150, 1e300]
OFFSETS = [0.0, 1.0, 1e10, -1e100, 1e200, -1e300]
#: Magnitudes of a single far point: the whole finite range.
FAR = st.one_of(st.sampled_from([1e6, 1e30, 1e200, 1e300, 1.7e308, -1e308]), st.floats(-1.7e308, 1.7e308, allow_nan=False))


@st.composite
def clouds(draw, max_points: int = 40) -> np.ndarray:
    """Points of one scale at an offset, with mixed scales, a single far point, or
    near-duplicates at a large offset mixed in; always finite."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n = draw(st.integers(4, max_points))
    scale, offset = draw(st.sampled_from(SCALES)), draw(st.sampled_from(OFFSETS))
    kind = draw(st.sampled_from(["plain", "far", "mixed", "near_duplicates"]))
    with np.errstate(all="ignore"):
        p = rng.uniform(-1, 1, (n, 3)) * scale + offset
        if kind == "far":
            p[draw(st.integers(0, n - 1)), draw(st.integers(0, 2))] = draw(FAR)
        elif kind == "mixed":
            p[: n // 2] *= draw(st.sampled_from(SCALES)) / scale
        elif kind == "near_duplicates":
            p[n // 2 :] = p[: n - n // 2] * (1 + 1e-15) + rng.uniform(-1, 1, (n - n // 2, 3)) * 1e-300
    p[~np.isfinite(p)] = 1e300
    return p


def refused_or(call):
    """`call()`, or None when it raises one of the accepted errors."""
    try:
        return call()
    except REFUSED:
        return None


def unit(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _mesh_of(field, bounds, method: str):
    """A small polygonization with `method` at bounds of any magnitude."""
    return refused_or(lambda: im.polygonize(field, bounds=bounds, resolution=6, method=method))


@CHECK
@given(clouds(), st.sampled_from(["global", "partition", "auto"]), st.booleans())
def _fits(p, method, exact):
    rng = np.random.default_rng(0)
    opts = {"method": method}
    if method == "partition":
        opts["partition_options"] = {"max_per_leaf": 8, "min_points": 4, "max_patch": 12}
    s = refused_or(lambda: im.VariationalSurface.fit(p, unit(rng, len(p)), **opts, exact=exact))
    refused_or(lambda: im.VariationalSurface.interpolate(p, rng.normal(size=len(p)), **opts))
    if s is not None:
        assert np.isfinite(s.bounds).all()
        refused_or(lambda: s.evaluate(p[:5]))
        _mesh_of(s, s.bounds, "octree")


def check_fits():
    _fits()


@CHECK
@given(clouds(max_points=12), st.integers(0, 2**32 - 1))
def _meshes(p, seed):
    rng = np.random.default_rng(seed)
    v, f = im.shapes.fibonacci_sphere(12)[0], None
    from scipy.spatial import ConvexHull

    v = p if len(p) >= 4 else v
    try:
        f = ConvexHull(v).simplices
    except Exception:
        f = rng.integers(0, len(v), (8, 3))
    refused_or(lambda: im.VariationalSurface.from_mesh(v, f))
    refused_or(lambda: im.subdivide(v, f, levels=1, surface=lambda q: np.linalg.norm(q, axis=1) - 1.0))
    refused_or(lambda: im.butterfly(v, f, levels=1))


def check_meshes():
    _meshes()


@CHECK
@given(clouds(), st.sampled_from(SCALES), st.sampled_from(["dense", "sparse", "tracking", "octree"]))
def _blobs(c, radius, method):
    b = refused_or(lambda: im.BlobField(c, radius))
    q = refused_or(lambda: im.BlobField.from_particles(c, radius))
    for field in (b, q):
        if field is not None:
            bounds = np.asarray(field.bounds)
            assert np.isfinite(bounds).all()
            _mesh_of(field, bounds, method)
            refused_or(lambda: field.evaluate(c[:5]))
            refused_or(lambda: pickle.loads(pickle.dumps(field)))


def check_blobs():
    _blobs()


@CHECK
@given(clouds(max_points=8), st.sampled_from(["dense", "octree", "tracking"]), st.integers(1, 40))
def _polygonize_bounds(p, method, resolution):
    lo, hi = p.min(axis=0), p.max(axis=0)
    sphere = lambda q: np.linalg.norm(q - p[0], axis=1) - 0.5 * np.abs(hi - lo).max()
    refused_or(lambda: im.polygonize(sphere, bounds=[lo, hi], resolution=resolution, method=method))
    blobs = refused_or(lambda: im.BlobField(p, 0.5))
    if blobs is not None:
        for m in ("sparse", "dense"):
            refused_or(lambda: im.polygonize(blobs, bounds=[lo, hi], resolution=resolution, method=m))
        # The tile functions: a window of the lattice, the blobs a tile keeps, a cut surface.
        refused_or(lambda: _core.polygonize(blobs, [lo, hi], resolution, method="sparse", window=[[0, 0, 0], [2, 2, 2]], boundary=True))
        lattice = refused_or(lambda: _core.lattice([lo, hi], resolution))
        if lattice is not None:
            cells, origin, cell = lattice
            index_start = refused_or(lambda: blobs._tile_primitives(origin, cell, cells, [2, 2, 2], 1e-6))
            if index_start is not None:
                index, start = index_start
                for a, b in zip(start[:-1], start[1:]):
                    refused_or(lambda: blobs._subset(index[a:b]))


def check_polygonize():
    _polygonize_bounds()


_SURFACES: dict = {}


def _saved(method: str):
    """A small fitted surface's state (made once per process)."""
    if method not in _SURFACES:
        p, n = im.shapes.fibonacci_sphere(200)
        opts = {"partition_options": {"max_per_leaf": 16, "min_points": 8, "max_patch": 40}} if method == "partition" else {}
        _SURFACES[method] = im.VariationalSurface.fit(p, n, method=method, **opts, exact=True)
    return _SURFACES[method]


@CHECK
@given(st.sampled_from(["global", "partition"]), st.data())
def _states(method, data):
    s = _saved(method)
    state = s.to_state()
    arrays = [k for k, v in state.items() if isinstance(v, np.ndarray) and v.dtype.kind == "f" and v.size]
    key = data.draw(st.sampled_from(arrays))
    a = state[key].copy()
    how = data.draw(st.sampled_from(["one", "scale"]))
    with np.errstate(all="ignore"):
        if how == "one":
            a.flat[data.draw(st.integers(0, a.size - 1))] = data.draw(FAR)
        else:
            a *= data.draw(st.sampled_from(SCALES))
    state[key] = a
    back = refused_or(lambda: im.VariationalSurface.from_state(state))
    if back is not None:
        refused_or(lambda: back.evaluate(np.zeros((2, 3))))
        _mesh_of(back, s.bounds, "octree")
    # The same through a file and through pickle.
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "s.npz")
        im.save(path, s)
        with np.load(path, allow_pickle=False) as z:
            saved = dict(z)
        if key in saved:
            saved[key] = a
            np.savez(path, **saved)
            refused_or(lambda: im.load(path))
    reduce, args = s.__reduce__()
    tampered = dict(args[0])
    tampered[key] = a
    refused_or(lambda: reduce(pickle.loads(pickle.dumps(tampered))))


def check_states():
    _states()


if __name__ == "__main__":
    globals()[sys.argv[1]]()
    print("ok")
