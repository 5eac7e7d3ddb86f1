"""polygonize(method="octree"): the hierarchical rejection of Cuno et al. (2004, §4.3) against plain
marching cubes — same mesh, watertight, exact and economical evaluation counts — on the shared meshes
and on Python callables; a case where the rejection test really fails and ``safety`` repairs it; and
the validation of the octree-only arguments."""

from __future__ import annotations

import math

import numpy as np
import pytest

from implicitmesh import VariationalSurface, compare, polygonize, shapes

from conftest import D, MESH_NAMES

BOX = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])

#: (bounds, resolution): the surface's own bounds (its bounding box with a margin) and the papers'
#: [-1, 1]³, each at 64³ and 128³.
GRIDS = [("own", 64), ("own", 128), ("box", 64), ("box", 128)]

#: Evaluations allowed, in % of the (n+1)³ lattice points that plain marching cubes evaluates:
#: the issue's 15 % at 64³, and at 128³ a bound near what is measured, to catch regressions.
#: Measured (d = 0.015, defaults): 2.3–6.5 % at 128³ over the surface's bounds, 2.7–7.4 % over
#: [-1, 1]³; 4.5–12.6 % and 5.2–14.4 % at 64³, the icosahedron always the largest (the paper's
#: test alone, `corner_test=False`: 4.6–12.6 %, 5.3–14.6 %, 8.3–24.8 %, 9.5–28.1 %). At 64³ the
#: icosahedron is below 15 % only because leaves are settled by signs: the corners of the cells
#: the surface crosses are 10.3 % (own bounds) and 12.0 % ([-1, 1]³) of the lattice, and the
#: octree also evaluates points to prove the cells near the surface empty.
MAX_PERCENT = {("own", 64): 15.0, ("box", 64): 15.0, ("own", 128): 7.5, ("box", 128): 8.0}

#: Cuno et al.'s evaluation shares at 128³ over [-1, 1]³ for models of the same names (issue 3's
#: target: ours below them). Measured with the defaults: knot 4.06 %, torus2 2.65 %.
PAPER_PERCENT = {"knot": 12.56, "torus2": 4.22}


class PointRecorder:
    """A callable field that forwards to `fn` and keeps a copy of every batch of points it is given."""

    def __init__(self, fn):
        self.fn = fn
        self.batches: list[np.ndarray] = []

    def __call__(self, points):
        self.batches.append(np.array(points, dtype=np.float64, copy=True))
        return self.fn(points)

    @property
    def points(self) -> np.ndarray:
        return np.concatenate(self.batches) if self.batches else np.zeros((0, 3))

    @property
    def distinct(self) -> int:
        """Number of distinct points (by exact coordinates; + 0.0 turns -0.0 into 0.0)."""
        rows = np.ascontiguousarray(self.points + 0.0).view(np.dtype((np.void, 3 * 8))).ravel()
        return len(np.unique(rows))


# ---------------------------------------------------------------------------------- shared meshes


@pytest.fixture(scope="module", params=MESH_NAMES)
def fitted(request, mesh_dir):
    """Each shared 800-vertex mesh fitted once (d = 0.015, default w = 0.75 d)."""
    import trimesh

    path = mesh_dir / f"{request.param}_800.ply"
    m = trimesh.load(path, process=False)
    v, f = np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)
    return request.param, VariationalSurface.from_mesh(v, f, d=D)


@pytest.fixture(scope="module", params=GRIDS, ids=[f"{b}-{n}" for b, n in GRIDS])
def polygonized(request, fitted):
    """(name, surface, grid, bounds, dense mesh, octree mesh), each polygonization done once."""
    name, surface = fitted
    kind, n = request.param
    bounds = surface.bounds if kind == "own" else BOX
    dense = polygonize(surface, bounds=bounds, resolution=n, method="dense", normals=False)
    octree = polygonize(surface, bounds=bounds, resolution=n, method="octree", normals=False)
    return name, surface, request.param, bounds, dense, octree


def test_octree_mesh_equals_dense_mesh(polygonized):
    name, _, grid, _, dense, octree = polygonized
    c = compare(dense, octree)
    assert c["common"] > 0
    assert (c["missing"], c["extra"]) == (0, 0), (name, grid, c)
    assert len(octree.faces) == len(dense.faces)


def test_octree_mesh_is_watertight(polygonized):
    name, _, grid, _, _, octree = polygonized
    tm = octree.to_trimesh(process=False)
    assert len(tm.faces) > 0
    assert tm.is_watertight, (name, grid)
    assert tm.is_winding_consistent, (name, grid)
    assert octree.volume > 0


def test_octree_evaluates_a_small_share_of_the_lattice(polygonized):
    name, _, grid, _, dense, octree = polygonized
    n = grid[1]
    stats = octree.stats
    assert stats["lattice_points"] == (n + 1) ** 3 == dense.stats["evaluations"]
    assert math.isclose(stats["evaluation_percent"], 100.0 * stats["evaluations"] / stats["lattice_points"])
    assert stats["evaluation_percent"] < MAX_PERCENT[grid], (name, grid, stats["evaluation_percent"])


@pytest.mark.parametrize("name", sorted(PAPER_PERCENT))
def test_evaluations_below_the_papers_share(name, mesh_dir):
    import trimesh

    path = mesh_dir / f"{name}_800.ply"
    m = trimesh.load(path, process=False)
    surface = VariationalSurface.from_mesh(np.asarray(m.vertices), np.asarray(m.faces, dtype=np.int64), d=D)
    octree = polygonize(surface, bounds=BOX, resolution=128, method="octree", normals=False)
    assert octree.stats["evaluation_percent"] < PAPER_PERCENT[name], octree.stats["evaluation_percent"]


@pytest.mark.parametrize("kind", ["own", "box"])
def test_evaluation_count_is_exact_and_each_point_is_evaluated_once(fitted, kind):
    """The same surface wrapped in a Python callable, at 64³: the wrapper sees exactly `evaluations`
    distinct points, none of them twice, and the mesh is the same."""
    name, surface = fitted
    bounds = surface.bounds if kind == "own" else BOX
    octree = polygonize(surface, bounds=bounds, resolution=64, method="octree", normals=False)
    recorder = PointRecorder(lambda p: surface.evaluate(p))
    via_callable = polygonize(recorder, bounds=bounds, resolution=64, method="octree", normals=False)
    seen = recorder.points
    assert len(seen) > 0
    assert recorder.distinct == len(seen), "some point was evaluated twice"
    assert octree.stats["evaluations"] == recorder.distinct, (name, kind)
    assert via_callable.stats["evaluations"] == recorder.distinct
    c = compare(octree, via_callable)
    assert c["common"] > 0
    assert (c["missing"], c["extra"]) == (0, 0), (name, kind, c)


# ------------------------------------------------------------------------- the rejection can fail

#: With w/d = 5/6, testing from the root's octants (r = √3/2) without the corner test, i.e. Cuno's
#: §4.3 exactly, drops blocks of torus2 that the surface crosses (without the repair, hundreds of
#: triangles were lost; fandisk a handful, spot, knot, star and the icosahedron none). A safety
#: factor of 1.1 already keeps the premise on torus2 (fandisk needs 1.25); 1.5 leaves a margin.
HOLE_MESH = "torus2"
SAFETY = 1.5


@pytest.fixture(scope="module")
def over_steep(mesh_dir):
    import trimesh

    path = mesh_dir / f"{HOLE_MESH}_800.ply"
    m = trimesh.load(path, process=False)
    surface = VariationalSurface.from_mesh(np.asarray(m.vertices), np.asarray(m.faces), d=D, w=D * 5 / 6)
    dense = polygonize(surface, bounds=BOX, resolution=128, method="dense", normals=False)
    return surface, dense


def test_paper_settings_with_w_over_d_5_6_are_repaired_and_safety_avoids_the_repair(over_steep):
    surface, dense = over_steep
    kwargs = dict(bounds=BOX, resolution=128, method="octree", normals=False, start_level=1, corner_test=False)
    # The §4.3 settings reject cells that hold the surface; the repair walks into them.
    repaired = polygonize(surface, **kwargs)
    assert repaired.stats["cells_repaired"] > 0, "expected the §4.3 settings to reject cells that hold the surface"
    c = compare(dense, repaired)
    assert (c["missing"], c["extra"]) == (0, 0)
    assert repaired.to_trimesh().is_watertight

    # A larger safety factor keeps the premise: nothing to repair, the same mesh.
    safe = polygonize(surface, safety=SAFETY, **kwargs)
    assert safe.stats["cells_repaired"] == 0
    c = compare(dense, safe)
    assert (c["missing"], c["extra"]) == (0, 0)


def test_defaults_have_no_holes_where_the_paper_settings_do(over_steep):
    surface, dense = over_steep
    octree = polygonize(surface, bounds=BOX, resolution=128, method="octree", normals=False)
    c = compare(dense, octree)
    assert (c["missing"], c["extra"]) == (0, 0)


def test_default_start_level_avoids_the_holes_of_a_coarse_start(mesh_dir):
    """Even with the default w = 0.75 d, starting the test at the root's octants drops blocks that
    hold the surface at some resolutions (the knot over its own bounds at 80³; 24³, 40³, 48³ and
    100³ too), which the repair then walks into; the default start level needs no repair."""
    import trimesh

    path = mesh_dir / "knot_800.ply"
    m = trimesh.load(path, process=False)
    surface = VariationalSurface.from_mesh(np.asarray(m.vertices), np.asarray(m.faces), d=D)
    kwargs = dict(bounds=surface.bounds, resolution=80, normals=False)
    dense = polygonize(surface, method="dense", **kwargs)
    coarse = polygonize(surface, method="octree", start_level=1, **kwargs)
    # The coarse start drops blocks the surface crosses; the repair recovers them.
    assert coarse.stats["cells_repaired"] > 0
    assert compare(dense, coarse)["missing"] == 0
    default = polygonize(surface, method="octree", **kwargs)
    assert default.stats["cells_repaired"] == 0
    c = compare(dense, default)
    assert (c["missing"], c["extra"]) == (0, 0)


# ------------------------------------------------------------------------------- Python callables

CALLABLES = {
    "sphere": shapes.Sphere(),
    "torus": shapes.Torus(),
    "sphere_offcentre": shapes.Sphere(center=(0.013, -0.021, 0.007), radius=0.7),
    "torus_offcentre": shapes.Torus(center=(0.011, 0.02, -0.013), major=0.55, minor=0.2),
}


@pytest.mark.parametrize("resolution", [37, 50, 64, 100])
@pytest.mark.parametrize("shape_name", sorted(CALLABLES))
def test_callable_signed_distances(shape_name, resolution):
    shape = CALLABLES[shape_name]
    dense = polygonize(shape, bounds=shape.bounds, resolution=resolution, method="dense", normals=False)
    octree = polygonize(shape, bounds=shape.bounds, resolution=resolution, method="octree", normals=False)
    c = compare(dense, octree)
    assert c["common"] > 0
    assert (c["missing"], c["extra"]) == (0, 0), c
    tm = octree.to_trimesh(process=False)
    assert tm.is_watertight
    assert tm.is_winding_consistent
    assert octree.euler_number == tm.euler_number == 2 - 2 * shape.genus
    assert octree.stats["evaluations"] < octree.stats["lattice_points"]


# ----------------------------------------------------------------------------------- validation

SPHERE = shapes.Sphere()


class NeverCalled:
    def __init__(self):
        self.calls = 0

    def __call__(self, points):
        self.calls += 1
        return SPHERE(points)


@pytest.mark.parametrize("option", [{"start_level": 2}, {"safety": 1.5}, {"corner_test": False}, {"corner_test": True}])
def test_octree_options_with_dense_raise(option):
    field = NeverCalled()
    with pytest.raises(ValueError, match="octree"):
        polygonize(field, bounds=SPHERE.bounds, resolution=16, method="dense", **option)
    assert field.calls == 0


@pytest.mark.parametrize("safety", [0.0, -0.0, -1.0, float("nan"), float("-inf")])
def test_non_positive_or_nan_safety_raises(safety):
    field = NeverCalled()
    with pytest.raises(ValueError, match="safety"):
        polygonize(field, bounds=SPHERE.bounds, resolution=16, method="octree", safety=safety)
    assert field.calls == 0
