"""Bad input raises ValueError (TypeError for a non-field) with a message naming the argument;
unusual but valid input (float32, lists, Fortran order, strided views) is converted, not refused,
and gives the same result as plain C-ordered float64."""

from __future__ import annotations

import numpy as np
import pytest

from implicitmesh import Ambiguity, VariationalSurface, polygonize, shapes

BOX = [[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]
SPHERE = shapes.Sphere()


@pytest.fixture(scope="module")
def data():
    return shapes.fibonacci_sphere(80)


@pytest.fixture(scope="module")
def mesh():
    """A small closed mesh (the icosphere of trimesh, 162 vertices) as arrays."""
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=2, radius=0.8)
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


@pytest.fixture(scope="module")
def surface(data):
    return VariationalSurface.fit(*data, exact=True)


def with_entry(a, index, value):
    b = np.array(a, dtype=np.float64, copy=True)
    b[index] = value
    return b


# --------------------------------------------------------------------------- fit / interpolate


def test_points_wrong_shape(data):
    p, n = data
    with pytest.raises(ValueError, match="points"):
        VariationalSurface.fit(p[:, :2], n, exact=True)
    with pytest.raises(ValueError, match="points"):
        VariationalSurface.fit(p.ravel(), n, exact=True)
    with pytest.raises(ValueError, match="points"):
        VariationalSurface.interpolate(p[:, :2], np.zeros(len(p)))


def test_normals_wrong_shape_or_count(data):
    p, n = data
    with pytest.raises(ValueError, match="normals"):
        VariationalSurface.fit(p, n[:-1], exact=True)
    with pytest.raises(ValueError, match="normals"):
        VariationalSurface.fit(p, n[:, :2], exact=True)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_points(data, bad):
    p, n = data
    with pytest.raises(ValueError, match="points"):
        VariationalSurface.fit(with_entry(p, (5, 1), bad), n, exact=True)
    with pytest.raises(ValueError, match="points"):
        VariationalSurface.interpolate(with_entry(p, (5, 1), bad), np.zeros(len(p)))


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_normals(data, bad):
    p, n = data
    with pytest.raises(ValueError, match="normals"):
        VariationalSurface.fit(p, with_entry(n, (7, 2), bad), exact=True)


def test_non_finite_values(data):
    p, _ = data
    with pytest.raises(ValueError, match="values"):
        VariationalSurface.interpolate(p, with_entry(np.zeros(len(p)), 3, np.nan))


def test_values_wrong_count_or_shape(data):
    p, _ = data
    with pytest.raises(ValueError, match="values"):
        VariationalSurface.interpolate(p, np.zeros(len(p) - 1))
    with pytest.raises(ValueError, match="values"):
        VariationalSurface.interpolate(p, np.zeros((len(p), 2)))


def test_fewer_than_four_points(data):
    p, n = data
    with pytest.raises(ValueError, match="points"):
        VariationalSurface.fit(p[:3], n[:3], exact=True)
    with pytest.raises(ValueError, match="points"):
        VariationalSurface.interpolate(p[:3], np.zeros(3))
    with pytest.raises(ValueError, match="points"):
        VariationalSurface.fit(np.zeros((0, 3)), np.zeros((0, 3)), exact=True)


def test_coplanar_points():
    rng = np.random.default_rng(0)
    flat = np.c_[rng.uniform(-1, 1, size=(30, 2)), np.zeros(30)]
    normals = np.tile([0.0, 0.0, 1.0], (30, 1))
    with pytest.raises(ValueError, match="points"):
        VariationalSurface.fit(flat, normals, exact=True)
    # The same plane tilted and shifted.
    rot, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    with pytest.raises(ValueError, match="points"):
        VariationalSurface.fit(flat @ rot.T + [0.3, -0.2, 0.5], normals @ rot.T, exact=True)
    with pytest.raises(ValueError, match="points"):
        VariationalSurface.interpolate(flat, rng.normal(size=30))
    # Collinear points too.
    line = np.outer(np.linspace(-1, 1, 10), [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="points"):
        VariationalSurface.fit(line, np.tile([0.0, 0.0, 1.0], (10, 1)), exact=True)


def test_duplicate_points_are_merged_with_a_warning(data):
    p, n = data
    dup = p.copy()
    dup[40] = dup[3]
    dup[41] = dup[5] + 1e-12
    with pytest.warns(UserWarning, match="2 data points"):
        s = VariationalSurface.fit(dup, n, exact=True)
    assert s.merged_points == 2
    kept = np.delete(dup, [40, 41], axis=0)
    assert np.abs(s.evaluate(kept)).max() < 1e-9
    with pytest.warns(UserWarning, match="merged"):
        s = VariationalSurface.interpolate(dup, np.arange(len(p), dtype=float))
    assert s.merged_points == 2
    # Merged values are averaged: points 3 and 40 had the values 3 and 40.
    assert s.evaluate(dup[3:4])[0] == pytest.approx(21.5, abs=1e-6)
    with pytest.raises(ValueError, match="merge_distance"):
        VariationalSurface.fit(p, n, merge_distance=-1.0, exact=True)
    with pytest.raises(ValueError, match="merge_distance"):
        VariationalSurface.interpolate(p, np.zeros(len(p)), merge_distance=np.nan)


def test_zero_length_normal(data):
    p, n = data
    with pytest.raises(ValueError, match="normals"):
        VariationalSurface.fit(p, with_entry(n, 11, 0.0), exact=True)


def test_unknown_kernel(data, mesh):
    p, n = data
    with pytest.raises(ValueError, match="kernel"):
        VariationalSurface.fit(p, n, kernel="gaussian", exact=True)
    with pytest.raises(ValueError, match="kernel"):
        VariationalSurface.interpolate(p, np.zeros(len(p)), kernel="gaussian")
    with pytest.raises(ValueError, match="kernel"):
        VariationalSurface.from_mesh(*mesh, kernel="gaussian")


@pytest.mark.parametrize("smoothing", [-1e-3, -1.0, np.nan, np.inf])
def test_bad_smoothing(data, smoothing):
    p, n = data
    with pytest.raises(ValueError, match="smoothing"):
        VariationalSurface.fit(p, n, smoothing=smoothing, exact=True)
    with pytest.raises(ValueError, match="smoothing"):
        VariationalSurface.interpolate(p, np.zeros(len(p)), smoothing=smoothing)


@pytest.mark.parametrize("d", [0.0, -0.01, np.nan, np.inf])
def test_bad_offset_d(data, d):
    p, n = data
    with pytest.raises(ValueError, match=r"^d: "):
        VariationalSurface.fit(p, n, d=d, exact=True)


@pytest.mark.parametrize("w", [0.0, np.nan, np.inf])
def test_bad_value_w(data, w):
    p, n = data
    with pytest.raises(ValueError, match=r"^w: "):
        VariationalSurface.fit(p, n, w=w, exact=True)


def test_fit_over_the_memory_limit(data, mesh):
    p, n = data
    with pytest.raises(ValueError, match="points|memory_limit"):
        VariationalSurface.fit(p, n, memory_limit=1000, exact=True)
    with pytest.raises(ValueError, match="points|memory_limit"):
        VariationalSurface.interpolate(p, np.zeros(len(p)), memory_limit=1000)
    with pytest.raises(ValueError, match="points|vertices|memory_limit"):
        VariationalSurface.from_mesh(*mesh, memory_limit=1000)


# --------------------------------------------------------------------------- from_mesh


def test_faces_out_of_range(mesh):
    v, f = mesh
    bad = f.copy()
    bad[10, 1] = len(v)
    with pytest.raises(ValueError, match="faces"):
        VariationalSurface.from_mesh(v, bad)


def test_faces_negative(mesh):
    v, f = mesh
    bad = f.copy()
    bad[10, 2] = -1
    with pytest.raises(ValueError, match="faces"):
        VariationalSurface.from_mesh(v, bad)


def test_faces_repeating_a_vertex(mesh):
    v, f = mesh
    bad = f.copy()
    bad[10, 1] = bad[10, 0]
    with pytest.raises(ValueError, match="faces"):
        VariationalSurface.from_mesh(v, bad)


def test_faces_wrong_shape_or_empty(mesh):
    v, f = mesh
    with pytest.raises(ValueError, match="faces"):
        VariationalSurface.from_mesh(v, f[:, :2])
    with pytest.raises(ValueError, match="faces"):
        VariationalSurface.from_mesh(v, np.zeros((0, 3), dtype=np.int64))


def test_faces_non_integer(mesh):
    """Fractional vertex indices are not silently truncated."""
    v, f = mesh
    with pytest.raises(ValueError, match="faces"):
        VariationalSurface.from_mesh(v, f + 0.5)


def test_vertices_bad(mesh):
    v, f = mesh
    with pytest.raises(ValueError, match="vertices"):
        VariationalSurface.from_mesh(v[:, :2], f)
    with pytest.raises(ValueError, match="vertices"):
        VariationalSurface.from_mesh(with_entry(v, (4, 0), np.nan), f)
    # A vertex no face uses.
    with pytest.raises(ValueError, match="vertices"):
        VariationalSurface.from_mesh(np.vstack([v, [[2.0, 2.0, 2.0]]]), f)


# --------------------------------------------------------------------------- evaluate / gradient


def test_evaluate_and_gradient_bad_points(surface):
    for method in (surface.evaluate, surface.gradient, surface):
        with pytest.raises(ValueError, match="points"):
            method(np.zeros((4, 2)))
        with pytest.raises(ValueError, match="points"):
            method(np.zeros(3))
        with pytest.raises(ValueError, match="points"):
            method(with_entry(np.zeros((4, 3)), (2, 1), np.nan))
        with pytest.raises(ValueError, match="points"):
            method(with_entry(np.zeros((4, 3)), (2, 1), np.inf))
        with pytest.raises(ValueError, match="points"):
            method("abc")


def test_evaluate_no_points(surface):
    assert surface.evaluate(np.zeros((0, 3))).shape == (0,)
    assert surface.gradient(np.zeros((0, 3))).shape == (0, 3)


# --------------------------------------------------------------------------- polygonize


@pytest.mark.parametrize(
    "resolution",
    [0, -1, -64, 1.5, 2.0, "abc", "64", True, False, None, (64, 64), (64, 64, 64, 64), (8, 8, 0), (8, 8.5, 8), (8, True, 8), 10**7, (8, 8, 10**7), 2**40],
    ids=repr,
)
def test_bad_resolution(resolution):
    with pytest.raises(ValueError, match="resolution"):
        polygonize(SPHERE, bounds=BOX, resolution=resolution)


@pytest.mark.parametrize("kwargs", [{"resolution": 100000}, {"resolution": 16, "memory_limit": 1000}, {"resolution": (1000, 1000, 100000)}])
def test_resolution_over_the_memory_limit(kwargs):
    with pytest.raises(ValueError, match="resolution|memory_limit"):
        polygonize(SPHERE, bounds=BOX, **kwargs)


@pytest.mark.parametrize("memory_limit", [0, -5, 1.5, True])
def test_bad_memory_limit(memory_limit):
    with pytest.raises(ValueError, match="memory_limit"):
        polygonize(SPHERE, bounds=BOX, resolution=8, memory_limit=memory_limit)


@pytest.mark.parametrize(
    "bounds",
    [
        [[1.0, 1.0, 1.0], [-1.0, -1.0, -1.0]],  # max < min
        [[-1.0, -1.0, -1.0], [1.0, -1.5, 1.0]],  # max < min on one axis
        [[-1.0, -1.0, 0.0], [1.0, 1.0, 0.0]],  # empty on one axis
        [-1.0, 1.0],
        [[-1.0, -1.0], [1.0, 1.0]],
        [[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]],
        [[-1.0, -1.0, -1.0]],
        [[-1.0, np.nan, -1.0], [1.0, 1.0, 1.0]],
        [[-1.0, -1.0, -1.0], [1.0, np.inf, 1.0]],
        "abc",
    ],
    ids=repr,
)
def test_bad_bounds(bounds):
    with pytest.raises(ValueError, match="bounds"):
        polygonize(SPHERE, bounds=bounds, resolution=8)


def test_bounds_required_for_a_plain_callable():
    with pytest.raises(ValueError, match="bounds"):
        polygonize(lambda p: SPHERE(p), resolution=8)


@pytest.mark.parametrize("method", ["no_such_method", "", "marching cubes", None, 3])
def test_unknown_method(method):
    with pytest.raises(ValueError, match="method"):
        polygonize(SPHERE, bounds=BOX, resolution=8, method=method)


@pytest.mark.parametrize("ambiguity", ["maybe", "", "separated", None, 0, True])
def test_unknown_ambiguity(ambiguity):
    with pytest.raises(ValueError, match="ambiguity"):
        polygonize(SPHERE, bounds=BOX, resolution=8, ambiguity=ambiguity)


@pytest.mark.parametrize("batch_size", [0, -1, 1.5, True, None])
def test_bad_batch_size(batch_size):
    with pytest.raises(ValueError, match="batch_size"):
        polygonize(SPHERE, bounds=BOX, resolution=8, batch_size=batch_size)


@pytest.mark.parametrize(
    "returns",
    [
        lambda p: np.zeros((len(p), 2)),
        lambda p: SPHERE(p)[:-1],
        lambda p: np.append(SPHERE(p), 1.0),
        lambda p: 1.0,
        lambda p: SPHERE(p)[None, :],
        lambda p: None,
    ],
    ids=["(N,2)", "N-1", "N+1", "scalar", "(1,N)", "None"],
)
def test_callable_returning_the_wrong_shape(returns):
    with pytest.raises(ValueError, match="field"):
        polygonize(returns, bounds=BOX, resolution=8)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_callable_returning_non_finite(bad):
    def field(p):
        v = SPHERE(p)
        v[(p[:, 0] > 0.5) & (p[:, 1] > 0.2)] = bad
        return v

    with pytest.raises(ValueError, match="field"):
        polygonize(field, bounds=BOX, resolution=8)


def test_callable_returning_nan_only_at_normal_probes():
    """NaN where the normals are estimated (off the lattice) is refused too, not turned into a
    silently wrong normal."""
    h = 2.0 / 8

    def field(p):
        v = SPHERE(p)
        on_lattice = np.all(np.abs(p / h - np.round(p / h)) < 1e-9, axis=1)
        v[~on_lattice] = np.nan
        return v

    with pytest.raises(ValueError, match="field"):
        polygonize(field, bounds=BOX, resolution=8)


class FieldFailure(Exception):
    pass


@pytest.mark.parametrize("exc_type", [FieldFailure, KeyError, ZeroDivisionError, RuntimeError])
def test_callable_raising_propagates_the_original_exception(exc_type):
    calls = []

    def field(p):
        calls.append(len(p))
        if len(calls) >= 2:
            raise exc_type("the field failed")
        return SPHERE(p)

    with pytest.raises(exc_type, match="the field failed"):
        polygonize(field, bounds=BOX, resolution=32, batch_size=2000)
    # Evaluation stopped at the first exception.
    assert len(calls) == 2


def test_callable_raising_during_normals_propagates():
    def field(p):
        if len(p) % 6 == 0 and not np.all(np.abs(p * 4 - np.round(p * 4)) < 1e-9):
            raise FieldFailure("normals failed")
        return SPHERE(p)

    with pytest.raises(FieldFailure, match="normals failed"):
        polygonize(field, bounds=BOX, resolution=8)


@pytest.mark.parametrize("field", [42, "sphere", None, np.zeros(3), [SPHERE]], ids=repr)
def test_non_callable_field(field):
    with pytest.raises(TypeError, match="field"):
        polygonize(field, bounds=BOX, resolution=8)


# --------------------------------------------------------------------------- accepted conversions


def query_points():
    return np.random.default_rng(8).uniform(-1.0, 1.0, size=(64, 3))


def test_float32_and_lists_accepted(data):
    p, n = data
    q = query_points()
    reference = VariationalSurface.fit(p, n, exact=True).evaluate(q)
    # float32 input: converted to float64 (the same as converting first).
    s32 = VariationalSurface.fit(p.astype(np.float32), n.astype(np.float32), exact=True)
    s32_ref = VariationalSurface.fit(p.astype(np.float32).astype(np.float64), n.astype(np.float32).astype(np.float64), exact=True)
    np.testing.assert_array_equal(s32.evaluate(q), s32_ref.evaluate(q))
    np.testing.assert_array_equal(s32.evaluate(q.astype(np.float32)), s32_ref.evaluate(q.astype(np.float32).astype(np.float64)))
    # Lists: the same as arrays.
    sl = VariationalSurface.fit(p.tolist(), n.tolist(), exact=True)
    np.testing.assert_array_equal(sl.evaluate(q.tolist()), reference)
    np.testing.assert_array_equal(sl.gradient(q.tolist()), VariationalSurface.fit(p, n, exact=True).gradient(q))
    si = VariationalSurface.interpolate(p.tolist(), [0.0] * len(p))
    assert np.max(np.abs(si.evaluate(p))) <= 1e-9
    # Integer input.
    cube = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)])
    VariationalSurface.interpolate(cube, np.arange(8))


def test_from_mesh_float32_int32_lists(mesh):
    v, f = mesh
    q = query_points()
    reference = VariationalSurface.from_mesh(v, f).evaluate(q)
    np.testing.assert_array_equal(VariationalSurface.from_mesh(v.tolist(), f.tolist()).evaluate(q), reference)
    np.testing.assert_array_equal(VariationalSurface.from_mesh(v, f.astype(np.int32)).evaluate(q), reference)
    np.testing.assert_array_equal(VariationalSurface.from_mesh(v, f.astype(np.uint16)).evaluate(q), reference)
    a = VariationalSurface.from_mesh(v.astype(np.float32), f)
    b = VariationalSurface.from_mesh(v.astype(np.float32).astype(np.float64), f)
    np.testing.assert_array_equal(a.evaluate(q), b.evaluate(q))


def fortran(a):
    out = np.asfortranarray(a)
    assert out.flags["F_CONTIGUOUS"] and not out.flags["C_CONTIGUOUS"]
    return out


def test_fortran_order_same_as_c_order_fit(data):
    p, n = data
    q = query_points()
    c = VariationalSurface.fit(p, n, exact=True)
    f = VariationalSurface.fit(fortran(p), fortran(n), exact=True)
    np.testing.assert_array_equal(f.constraints["points"], c.constraints["points"])
    np.testing.assert_array_equal(f.evaluate(q), c.evaluate(q))
    np.testing.assert_array_equal(c.evaluate(fortran(q)), c.evaluate(q))
    np.testing.assert_array_equal(c.gradient(fortran(q)), c.gradient(q))
    # Other non-contiguous layouts: a strided view and a transposed view.
    wide = np.zeros((len(p), 6))
    wide[:, ::2] = p
    np.testing.assert_array_equal(VariationalSurface.fit(wide[:, ::2], n, exact=True).evaluate(q), c.evaluate(q))
    np.testing.assert_array_equal(c.evaluate(np.ascontiguousarray(q.T).T), c.evaluate(q))
    np.testing.assert_array_equal(c.evaluate(q[::-1])[::-1], c.evaluate(q))


def test_fortran_order_same_as_c_order_interpolate(data):
    p, _ = data
    values = np.random.default_rng(1).normal(size=len(p))
    q = query_points()
    c = VariationalSurface.interpolate(p, values)
    f = VariationalSurface.interpolate(fortran(p), values[::-1].copy()[::-1])
    np.testing.assert_array_equal(f.evaluate(q), c.evaluate(q))


def test_fortran_order_same_as_c_order_from_mesh(mesh):
    v, f = mesh
    q = query_points()
    c = VariationalSurface.from_mesh(v, f)
    fo = VariationalSurface.from_mesh(fortran(v), fortran(f))
    np.testing.assert_array_equal(fo.evaluate(q), c.evaluate(q))


def test_fortran_order_same_as_c_order_polygonize():
    b = np.array(BOX)
    c = polygonize(SPHERE, bounds=b, resolution=12)
    f = polygonize(SPHERE, bounds=fortran(b), resolution=12)
    np.testing.assert_array_equal(f.vertices, c.vertices)
    np.testing.assert_array_equal(f.faces, c.faces)
    # A callable returning an (N, 1) Fortran-ordered or strided array is read correctly.
    g = polygonize(lambda p: np.asfortranarray(SPHERE(p)[:, None]), bounds=b, resolution=12)
    np.testing.assert_array_equal(g.vertices, c.vertices)

    def strided(p):
        out = np.zeros((len(p), 2))
        out[:, 1] = SPHERE(p)
        return out[:, 1]

    s = polygonize(strided, bounds=b, resolution=12)
    np.testing.assert_array_equal(s.vertices, c.vertices)
    np.testing.assert_array_equal(s.faces, c.faces)


def test_polygonize_accepts_lists_float32_and_numpy_ints():
    c = polygonize(SPHERE, bounds=np.array(BOX), resolution=12)
    for kwargs in (
        {"bounds": BOX, "resolution": [12, 12, 12]},
        {"bounds": np.array(BOX, dtype=np.float32), "resolution": np.int64(12)},
        {"bounds": np.array(BOX), "resolution": (np.int32(12),) * 3, "batch_size": np.int64(5000)},
        {"bounds": np.array(BOX), "resolution": 12, "ambiguity": Ambiguity.SEPARATE},
    ):
        m = polygonize(SPHERE, **kwargs)
        np.testing.assert_array_equal(m.vertices, c.vertices)
        np.testing.assert_array_equal(m.faces, c.faces)
    # A callable returning a list or float32 values.
    m = polygonize(lambda p: SPHERE(p).tolist(), bounds=BOX, resolution=12)
    np.testing.assert_array_equal(m.faces, c.faces)
    m32 = polygonize(lambda p: SPHERE(p).astype(np.float32), bounds=BOX, resolution=12)
    assert m32.to_trimesh().is_watertight


RUST_WORDS = ("DVec3", "Vec<", "usize", "f64", "u32", "i64", "Some(", "Err(", "Ok(", "::", "panicked")


def test_error_messages_are_in_python_terms(data, mesh):
    """Messages name arguments and values as Python users write them: no Rust types leak."""
    p, n = data
    v, f = mesh
    blobs_centres = np.zeros((3, 3))
    calls = [
        lambda: polygonize(SPHERE, bounds=[[1, 1, 1], [-1, -1, -1]], resolution=8),
        lambda: polygonize(SPHERE, bounds=[[0, 0, 0], [0, 1, 1]], resolution=8),
        lambda: polygonize(SPHERE, bounds=BOX, resolution=0),
        lambda: polygonize(SPHERE, bounds=BOX, resolution=[8, 8]),
        lambda: polygonize(SPHERE, bounds=BOX, resolution=10**7),
        lambda: polygonize(SPHERE, bounds=BOX, resolution=8, method="octree", safety=-1.0),
        lambda: polygonize(lambda q: np.zeros(len(q) + 1), bounds=BOX, resolution=8),
        lambda: VariationalSurface.fit(p[:3], n[:3], exact=True),
        lambda: VariationalSurface.fit(p, n[:-1], exact=True),
        lambda: VariationalSurface.fit(with_entry(p, (0, 0), np.nan), n, exact=True),
        lambda: VariationalSurface.fit(p, np.zeros_like(n), exact=True),
        lambda: VariationalSurface.fit(p, n, kernel="gaussian", exact=True),
        lambda: VariationalSurface.from_mesh(v, np.array([[0, 0, 1]])),
        lambda: VariationalSurface.from_mesh(v, f + len(v)),
        lambda: __import__("implicitmesh").BlobField(blobs_centres, -1.0),
        lambda: __import__("implicitmesh").BlobField(blobs_centres, [1.0, 2.0]),
    ]
    for i, call in enumerate(calls):
        with pytest.raises(ValueError) as info:
            call()
        message = str(info.value)
        assert not any(w in message for w in RUST_WORDS), (i, message)


def test_complex_input_is_refused_not_truncated(data):
    p, n = data
    with pytest.raises(ValueError, match="points.*complex"):
        VariationalSurface.fit(p.astype(complex), n, exact=True)
    with pytest.raises(ValueError, match="shape \\(5, 2\\)"):
        VariationalSurface.fit(np.zeros((5, 2)), np.zeros((5, 2)), exact=True)
