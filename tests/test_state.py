"""Fitted fields pickle and save to .npz, and come back evaluating to the same bits."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import implicitmesh as im

BOX = [[-1, -1, -1], [1, 1, 1]]


@pytest.fixture(scope="module", params=["global", "partition"])
def surface(request):
    p, n = im.shapes.fibonacci_sphere(1200)
    return im.VariationalSurface.fit(p * 0.8, n, method=request.param, exact=True)


@pytest.fixture(scope="module")
def queries():
    return np.random.default_rng(3).uniform(-1, 1, (2000, 3))


def test_a_pickled_surface_evaluates_to_the_same_bits(surface, queries):
    back = pickle.loads(pickle.dumps(surface))
    assert back.method == surface.method and back.kernel == surface.kernel
    assert np.array_equal(back.evaluate(queries), surface.evaluate(queries))
    assert np.array_equal(back.gradient(queries), surface.gradient(queries))
    assert back.residual == surface.residual
    a = im.polygonize(surface, bounds=BOX, resolution=32, method="octree")
    b = im.polygonize(back, bounds=BOX, resolution=32, method="octree")
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)


def test_a_saved_surface_loads_back(surface, queries, tmp_path):
    im.save(tmp_path / "s.npz", surface)
    back = im.load(tmp_path / "s.npz")
    assert isinstance(back, im.VariationalSurface)
    assert np.array_equal(back.evaluate(queries), surface.evaluate(queries))
    for k, v in surface.constraints.items():
        assert np.array_equal(back.constraints[k], v)


def test_a_blob_field_pickles_and_saves_after_an_update(queries, tmp_path):
    rng = np.random.default_rng(5)
    b = im.BlobField(rng.uniform(-0.5, 0.5, (300, 3)), rng.uniform(0.1, 0.2, 300), threshold=0.4, voxel_size=0.7)
    b.update(rng.uniform(-0.5, 0.5, (300, 3)))
    for back in (pickle.loads(pickle.dumps(b)), _saved(b, tmp_path)):
        assert np.array_equal(back.evaluate(queries), b.evaluate(queries))
        assert back.voxel_size == b.voxel_size and back.threshold == b.threshold


def _saved(field, tmp_path):
    im.save(tmp_path / "b.npz", field)
    return im.load(tmp_path / "b.npz")


def test_states_no_fit_makes_are_refused(surface):
    good = surface.to_state()
    cases = {
        "missing key": {k: v for k, v in good.items() if k != "residual"},
        "other format": {**good, "format": 99},
        "unknown method": {**good, "method": "magic"},
        "short array": {**good, "constraint_values": good["constraint_values"][:-1]},
        "nan": {**good, "constraint_points": np.full_like(good["constraint_points"], np.nan)},
    }
    if good["method"] == "global":
        cases["bad weights"] = {**good, "normalized_weights": good["normalized_weights"][:-1]}
    else:
        cases["bad patches"] = {**good, "patch_radius": good["patch_radius"][:-1]}
        index = good["patch_index"].copy()
        index[0] = len(good["constraint_values"])
        cases["index past the constraints"] = {**good, "patch_index": index}
        cases["index not uint32"] = {**good, "patch_index": good["patch_index"].astype(np.int64)}
        cases["short index"] = {**good, "patch_index": good["patch_index"][:-1]}
    for what, state in cases.items():
        with pytest.raises(ValueError, match="state|constraint"):
            im.VariationalSurface.from_state(state)
            pytest.fail(what)


def test_load_refuses_other_files(tmp_path):
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(ValueError, match="path"):
        im.load(tmp_path / "other.npz")
    with pytest.raises(ValueError, match="field"):
        im.save(tmp_path / "f.npz", lambda p: p[:, 0])


def _format_1(state: dict) -> dict:
    """A format-3 partition state in format 1, where every patch kept its normalised centres
    (computed as the fit does: (c − shift) · scale per coordinate) and every data point its
    normal constraint (no ``constraint_normal_of``)."""
    start, shared = state["patch_start"], state["patch_shared"]
    points, index = state["constraint_points"], state["patch_index"]
    own, shift, scale = state["patch_normalized_centers"], state["patch_shift"].reshape(-1, 3), state["patch_scale"]
    runs, at_index, at_own = [], 0, 0
    for k in range(len(shared)):
        n = start[k + 1] - start[k]
        if shared[k]:
            runs.append((points[index[at_index:at_index + n]] - shift[k]) * scale[k])
            at_index += n
        else:
            runs.append(own[at_own:at_own + n])
            at_own += n
    dropped = ("patch_index", "patch_shared", "constraint_normal_of")
    old = {k: v for k, v in state.items() if k not in dropped}
    return {**old, "format": 1, "patch_normalized_centers": np.concatenate(runs)}


def test_partition_patches_keep_indices_into_the_constraints(queries):
    p, n = im.shapes.fibonacci_sphere(1200)
    s = im.VariationalSurface.fit(p * 0.8, n, method="partition", exact=True)
    state = s.to_state()
    assert state["format"] == 3 and state["patch_index"].dtype == np.uint32
    # Every data point has its normal constraint, right after the data points.
    boundary = state["constraint_boundary"]
    assert np.array_equal(state["constraint_normal_of"], np.arange(boundary))
    shared = state["patch_shared"].astype(bool)
    sizes = np.diff(state["patch_start"])
    assert shared.sum() > 20 and len(state["patch_index"]) == sizes[shared].sum()
    # Only the plane patches (5 points of their own each) keep centres.
    assert len(state["patch_normalized_centers"]) == 5 * (~shared).sum()
    assert set(sizes[~shared]) <= {5}
    # A state of format 1 (every patch's normalised centres) loads to the same bits; its
    # centres take more than five times the bytes of the indices.
    old = _format_1(state)
    back = im.VariationalSurface.from_state(old)
    assert np.array_equal(back.evaluate(queries), s.evaluate(queries))
    assert np.array_equal(back.gradient(queries), s.gradient(queries))
    assert old["patch_normalized_centers"].nbytes > 5 * state["patch_index"].nbytes
    assert back.to_state()["patch_normalized_centers"].shape == old["patch_normalized_centers"].shape
    assert np.array_equal(back.to_state()["constraint_normal_of"], state["constraint_normal_of"])
    # Normal constraints named out of order are refused, by the state's name.
    bad = {**state, "constraint_normal_of": state["constraint_normal_of"][::-1].copy()}
    with pytest.raises(ValueError, match="constraint_normal_of"):
        im.VariationalSurface.from_state(bad)
