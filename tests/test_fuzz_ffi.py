"""Fuzzing across the FFI: random arrays (shapes, dtypes, strides, NaN/inf, huge and tiny values),
degenerate meshes and random parameters thrown at every public function. Each call returns a
result or raises ValueError/TypeError, never crashes or hangs; a non-contiguous array gives the
same answer as its contiguous copy; and one field polygonized from 8 Python threads at once gives
8 identical meshes."""

from __future__ import annotations

import re
import threading
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import implicitmesh as im

BOX = [[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]
FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

DTYPES = st.sampled_from([np.float64, np.float32, np.int64, np.int32, np.uint8, np.bool_, np.complex128, object])
SPECIAL = st.sampled_from([0.0, -0.0, 1.0, -1.0, np.nan, np.inf, -np.inf, 1e300, -1e300, 1e-300, 5e-324])


def arrays(max_rows: int = 12):
    """Arrays of any dtype and a shape near (N, 3), with special values mixed in."""
    shapes = st.one_of(
        st.tuples(st.integers(0, max_rows), st.sampled_from([3])),
        st.tuples(st.integers(0, max_rows), st.integers(0, 5)),
        st.tuples(st.integers(0, max_rows)),
        st.tuples(st.integers(0, 3), st.integers(0, 3), st.integers(0, 3)),
    )
    floats = st.one_of(st.floats(-10, 10, allow_nan=False), SPECIAL)
    return st.builds(_cast, hnp.arrays(np.float64, shapes, elements=floats), DTYPES, st.booleans())


def _cast(a, dtype, strided):
    if dtype is object:
        b = a.astype(object)
    else:
        with np.errstate(all="ignore"):
            b = a.astype(dtype)
    if strided and b.ndim >= 1 and b.shape[0] > 1:
        b = np.repeat(b, 2, axis=0)[::2]
    return b


def survives(call):
    """Runs `call`; an error must be ValueError or TypeError."""
    try:
        return call()
    except (ValueError, TypeError):
        return None


def refused_naming(call, *names):
    """Runs `call`; an error must be a ValueError or TypeError whose message names one of the
    arguments `names` (as Python calls them); returns the result, or None when refused."""
    try:
        return call()
    except (ValueError, TypeError) as e:
        message = str(e)
        assert any(re.search(rf"\b{name}\b", message) for name in names), f"{type(e).__name__} names none of {names}: {message}"
        return None


@pytest.fixture(scope="module")
def surface():
    return im.VariationalSurface.fit(*im.shapes.fibonacci_sphere(60), exact=True)


@pytest.fixture(scope="module")
def blobs():
    return im.BlobField(np.random.default_rng(1).uniform(-0.5, 0.5, (20, 3)), 0.3)


@FUZZ
@given(points=arrays(), normals=arrays())
def test_fit_takes_anything(points, normals):
    """Any arrays: a fit, which evaluates to finite values at its points, or a refusal naming
    the argument."""
    values = normals[:, 0] if normals.ndim == 2 and normals.shape[1] else normals
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # merged points
        for fit in (
            refused_naming(lambda: im.VariationalSurface.fit(points, normals, exact=True), "points", "normals"),
            refused_naming(lambda: im.VariationalSurface.interpolate(points, values), "points", "values"),
        ):
            if fit is not None:
                assert isinstance(fit, im.VariationalSurface) and len(fit) >= 4
                p = np.asarray(points, dtype=np.float64)
                out = fit.evaluate(p)
                assert out.shape == (len(points),)
                assert np.all(np.isfinite(out)) or np.abs(p).max() > 1e100


SPHERE_POINTS, SPHERE_NORMALS = im.shapes.fibonacci_sphere(40)


@FUZZ
@given(
    rows=st.lists(st.integers(0, 39), min_size=12, max_size=40, unique=True),
    dtype=st.sampled_from([np.float64, np.float32]),
    strided=st.booleans(),
)
def test_fit_takes_every_valid_layout(rows, dtype, strided):
    """Valid points with normals, in any order, float64 or float32, strided or not: always a
    fit, which interpolates its points (zero there) and is negative at the centre."""
    p = _cast(SPHERE_POINTS[rows], dtype, strided)
    n = _cast(SPHERE_NORMALS[rows], dtype, strided)
    fit = im.VariationalSurface.fit(p, n, exact=True)
    values = fit.evaluate(np.asarray(p, dtype=np.float64))
    assert values.shape == (len(rows),)
    assert np.abs(values).max() < 1e-6
    assert fit.evaluate(np.zeros((1, 3)))[0] < 0


@FUZZ
@given(points=arrays(40))
def test_evaluate_takes_anything(surface, blobs, points):
    for field in (surface, blobs):
        for method in (field.evaluate, field.gradient):
            out = survives(lambda: method(points))
            if out is not None:
                assert out.shape[0] == points.shape[0]


@FUZZ
@given(
    vertices=arrays(10),
    faces=st.one_of(
        hnp.arrays(np.int64, st.tuples(st.integers(0, 12), st.sampled_from([3, 4])), elements=st.integers(-2, 12)),
        hnp.arrays(np.int32, st.tuples(st.integers(0, 12), st.just(3)), elements=st.integers(0, 9)),
        hnp.arrays(np.float64, st.tuples(st.integers(0, 12), st.just(3)), elements=st.floats(0, 9)),
    ),
)
def test_meshes_take_anything(vertices, faces):
    """Any arrays: a fit of the mesh and its butterfly levels of the right shapes, or refusals
    naming the argument."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # merged vertices
        fit = refused_naming(lambda: im.VariationalSurface.from_mesh(vertices, faces), "vertices", "faces")
    if fit is not None:
        p = np.asarray(vertices, dtype=np.float64)
        out = fit.evaluate(p)
        assert out.shape == (len(vertices),)
        assert np.all(np.isfinite(out)) or np.abs(p).max() > 1e100
    levels = refused_naming(lambda: im.butterfly(vertices, faces, levels=1), "vertices", "faces")
    if levels is not None:
        assert len(levels) == 2
        control, fine = levels
        assert control.vertices.shape == (len(vertices), 3) and control.faces.shape == (len(faces), 3)
        assert fine.faces.shape == (4 * len(faces), 3) and fine.faces.dtype == np.int64
        assert fine.vertices.shape[1] == 3 and len(fine.vertices) >= len(vertices)
        assert np.array_equal(fine.vertices[: len(vertices)], control.vertices)


def test_meshes_take_a_valid_mesh():
    """The shapes the two checks above assert, on a mesh that must be taken."""
    v, f = _octahedron()
    fit = im.VariationalSurface.from_mesh(v, f)
    assert np.abs(fit.evaluate(v)).max() < 1e-6
    control, fine = im.butterfly(v, f, levels=1)
    assert fine.faces.shape == (32, 3) and len(fine.vertices) == 6 + 12


def _octahedron():
    v = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float) * 0.8
    f = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    return v, f


DEGENERATE = {
    "flipped face": lambda v, f: (v, np.vstack([f[:1, ::-1], f[1:]])),
    "duplicate face": lambda v, f: (v, np.vstack([f, f[:1]])),
    "isolated vertex": lambda v, f: (np.vstack([v, [[0.1, 0.2, 0.3]]]), f),
    "non-manifold edge": lambda v, f: (v, np.vstack([f, [[0, 2, 5]], [[0, 2, 1]]])),
    "open": lambda v, f: (v, f[:-1]),
    "zero-area face": lambda v, f: (np.vstack([v, v[:1]]), np.vstack([f, [[0, 6, 2]]])),
}


@pytest.mark.parametrize("kind", sorted(DEGENERATE))
def test_degenerate_meshes(kind):
    v, f = DEGENERATE[kind](*_octahedron())
    s = survives(lambda: im.VariationalSurface.from_mesh(v, f))
    if s is not None:
        assert np.all(np.isfinite(s.evaluate(v)))
    survives(lambda: im.subdivide(v, f, levels=1, field=im.shapes.Sphere(radius=0.8)))
    survives(lambda: im.butterfly(v, f, levels=1))


@FUZZ
@given(
    bounds=arrays(3),
    resolution=st.one_of(st.integers(-3, 24), st.floats(-2, 30), st.lists(st.integers(-1, 12), max_size=4), st.none(), st.text(max_size=3)),
    method=st.sampled_from(["dense", "sparse", "octree", "tracking", "DENSE", "bogus", "", 3]),
    safety=st.one_of(st.none(), st.floats(allow_nan=True, allow_infinity=True)),
    start_level=st.one_of(st.none(), st.integers(-2, 40)),
    batch_size=st.one_of(st.integers(-2, 300), st.just(262144)),
)
def test_polygonize_takes_anything(surface, blobs, bounds, resolution, method, safety, start_level, batch_size):
    for field in (surface, blobs, im.shapes.Sphere()):
        options = {}
        if method in ("octree", "OCTREE"):
            options = dict(safety=safety, start_level=start_level)
        mesh = survives(
            lambda: im.polygonize(field, bounds=bounds, resolution=resolution, method=method, batch_size=batch_size, **options)
        )
        if mesh is not None:
            assert mesh.faces.dtype == np.int64 and mesh.vertices.dtype == np.float64
            assert mesh.faces.size == 0 or mesh.faces.max() < len(mesh.vertices)
            assert np.all(np.isfinite(mesh.vertices))


@pytest.mark.parametrize("result", ["wrong length", "nan", "2-d", "strings", "raises"])
def test_callables_returning_nonsense(result):
    def field(p):
        r = np.linalg.norm(p, axis=1) - 0.5
        if result == "wrong length":
            return r[:-1]
        if result == "nan":
            r[len(r) // 2] = np.nan
            return r
        if result == "2-d":
            return r[:, None].repeat(2, axis=1)
        if result == "strings":
            return np.array(["x"] * len(r))
        raise ZeroDivisionError("from the callable")

    for method in ("dense", "octree", "tracking"):
        expected = ZeroDivisionError if result == "raises" else (ValueError, TypeError)
        with pytest.raises(expected):
            im.polygonize(field, bounds=BOX, resolution=12, method=method, seeds=[[0, 0, 0]] if method == "tracking" else None)


@FUZZ
@given(step=st.integers(2, 4), order=st.sampled_from(["C", "F"]), dtype=st.sampled_from([np.float64, np.float32]))
def test_strided_and_fortran_input_give_the_contiguous_answer(surface, blobs, step, order, dtype):
    rng = np.random.default_rng(step)
    base = rng.uniform(-1, 1, (30 * step, 3)).astype(dtype)
    view = np.asarray(base[::step], order=order)
    copy = np.ascontiguousarray(view, dtype=np.float64)
    for field in (surface, blobs):
        np.testing.assert_array_equal(field.evaluate(view), field.evaluate(copy))
        np.testing.assert_array_equal(field.gradient(view), field.gradient(copy))
    # A transposed (3, N) view read as (N, 3) through .T is not C-contiguous either.
    t = np.ascontiguousarray(copy.T).T
    np.testing.assert_array_equal(surface.evaluate(t), surface.evaluate(copy))


def test_eight_threads_polygonizing_one_field_get_eight_equal_meshes(surface, blobs):
    for field, method in ((surface, "octree"), (surface, "dense"), (blobs, "sparse"), (blobs, "tracking")):
        results: list = [None] * 8
        barrier = threading.Barrier(8)

        def work(i):
            barrier.wait()
            results[i] = im.polygonize(field, bounds=BOX, resolution=40, method=method)

        threads = [threading.Thread(target=work, args=(i,)) for i in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        first = results[0]
        for m in results[1:]:
            np.testing.assert_array_equal(m.vertices, first.vertices)
            np.testing.assert_array_equal(m.faces, first.faces)
            np.testing.assert_array_equal(m.normals, first.normals)
