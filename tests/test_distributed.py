"""implicitmesh.distributed: tiled polygonization on a Dask LocalCluster of two worker processes
gives the single-machine mesh, triangle for triangle and bit for bit (vertices, normals, vertex
count, watertight), for blob fields and variational surfaces, with output=DIR and weld, tiles
that do not divide the lattice, tiles of one cell, a worker memory limit, and bad input."""

from __future__ import annotations

import json
import os
import signal
import sys
import threading
import time

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")

import implicitmesh as im
from implicitmesh import distributed as imd
from implicitmesh.distributed import _plan, _run, _tile, _transport
from implicitmesh import shapes

from conftest import genus_of

BOX = [[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]

#: Memory limit of each worker: below the dense values of the 512³ lattice of
#: test_tiles_fit_where_the_whole_lattice_does_not (513³ × 8 bytes ≈ 1.08 GB).
WORKER_MEMORY = 900 * 2**20


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, memory_limit=WORKER_MEMORY, dashboard_address=":0"
    )
    with distributed.Client(cluster) as c:
        yield c
    cluster.close()


@pytest.fixture(scope="module")
def blobs():
    rng = np.random.default_rng(5)
    return im.BlobField(rng.uniform(-0.6, 0.6, (60, 3)), rng.uniform(0.2, 0.35, 60), rng.uniform(0.8, 1.2, 60))


@pytest.fixture(scope="module")
def knot():
    v, f = shapes.load_model("knot")
    return im.VariationalSurface.from_mesh(v, f, method="global"), im.VariationalSurface.from_mesh(v, f, method="partition")


def triangles(mesh: im.Mesh) -> np.ndarray:
    """The mesh's triangles as rows of nine coordinate bit patterns, each rotated to start at its
    smallest corner (orientation kept), sorted: equal for equal triangle multisets."""
    t = mesh.vertices[mesh.faces].view(np.uint64).reshape(-1, 3, 3)
    keys = [tuple(map(tuple, tri)) for tri in t]
    rows = []
    for k in keys:
        m = min(range(3), key=lambda i: k[i])
        rows.append(k[m:] + k[:m])
    return np.array(sorted(rows), dtype=np.uint64).reshape(-1, 9)


def normals_by_position(mesh: im.Mesh) -> dict:
    return {tuple(p): tuple(n) for p, n in zip(mesh.vertices.view(np.uint64).reshape(-1, 3), mesh.normals.view(np.uint64).reshape(-1, 3))}


def assert_same_mesh(tiled: im.Mesh, whole: im.Mesh) -> None:
    assert len(whole.faces) > 0
    assert len(tiled.faces) == len(whole.faces)
    assert len(tiled.vertices) == len(whole.vertices)
    assert np.array_equal(triangles(tiled), triangles(whole))
    assert normals_by_position(tiled) == normals_by_position(whole)
    assert im.compare(whole, tiled) == {"missing": 0, "extra": 0, "common": len(whole.faces)}
    assert tiled.euler_number == whole.euler_number


@pytest.mark.parametrize("method", ["sparse", "dense", "octree", "tracking"])
def test_blobs_equal_one_machine(client, blobs, method):
    whole = im.polygonize(blobs, bounds=BOX, resolution=48, method=method)
    tiled = imd.polygonize(blobs, bounds=BOX, resolution=48, method=method, client=client, tile=16)
    assert_same_mesh(tiled, whole)
    assert tiled.to_trimesh().is_watertight
    assert tiled.stats["tiles"] > 1


def test_sph_colour_field_equals_one_machine(client):
    # The tiles keep the field's kernel (cubic spline) and per-particle strengths.
    rng = np.random.default_rng(5)
    g = np.stack(np.meshgrid(*[np.arange(8) * 0.1] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    field = im.BlobField.from_particles(g + rng.uniform(-0.01, 0.01, g.shape) - 0.35, 0.05)
    assert field.kernel == "cubic_spline"
    whole = im.polygonize(field, bounds=BOX, resolution=40, method="sparse")
    tiled = imd.polygonize(field, bounds=BOX, resolution=40, method="sparse", client=client, tile=16)
    assert_same_mesh(tiled, whole)
    assert tiled.to_trimesh().is_watertight


@pytest.mark.parametrize("kind", ["global", "partition"])
def test_variational_surface_equals_one_machine(client, knot, kind):
    surface = knot[0] if kind == "global" else knot[1]
    assert surface.method == kind
    for method in ("dense", "octree"):
        whole = im.polygonize(surface, resolution=40, method=method)
        tiled = imd.polygonize(surface, resolution=40, method=method, client=client, tile=13)
        assert_same_mesh(tiled, whole)
        assert tiled.to_trimesh().is_watertight
        assert genus_of(tiled.euler_number) == 1


def test_projected_vertices_equal_one_machine(client, knot, blobs):
    """project=True moves each vertex on its own position and the field's values there, which
    cut fields give bit for bit: tiles weld to the single machine's projected mesh."""
    for field, method, kw in ((knot[1], "octree", {}), (blobs, "sparse", {"bounds": BOX})):
        whole = im.polygonize(field, resolution=40, method=method, project=True, **kw)
        tiled = imd.polygonize(field, resolution=40, method=method, client=client, tile=13, project=True, **kw)
        assert_same_mesh(tiled, whole)
        assert tiled.to_trimesh().is_watertight


def test_projection_is_refused_with_output_and_checks_its_faces(client, blobs, tmp_path):
    with pytest.raises(ValueError, match="project"), pytest.warns(DeprecationWarning, match="write_tiles"):
        imd.polygonize(blobs, bounds=BOX, resolution=16, client=client, tile=8, project=True, output=tmp_path)
    with pytest.raises(TypeError, match="project"):
        imd.write_tiles(blobs, tmp_path, bounds=BOX, resolution=16, client=client, tile=8, project=True)
    with pytest.raises(ValueError, match="project"):
        imd.polygonize(blobs, bounds=BOX, resolution=16, client=client, tile=8, project="yes")
    with pytest.raises(ValueError, match="faces"):
        im._core.project_mesh(blobs, BOX, 16, np.zeros((3, 3)), [[0, 1, 3]])


def test_cut_fields_evaluate_alike_in_their_box(blobs, knot):
    lo, hi = np.array([-0.5, -0.2, 0.0]), np.array([0.1, 0.3, 0.4])
    points = lo + (hi - lo) * np.random.default_rng(2).random((500, 3))
    points = np.vstack([points, lo, hi])
    for field in (blobs, knot[1]):
        part = imd.cut_field(field, lo, hi)
        assert np.array_equal(part(points).view(np.uint64), field(points).view(np.uint64))
        assert np.array_equal(part.gradient(points).view(np.uint64), field.gradient(points).view(np.uint64))
    assert 0 < len(imd.cut_field(blobs, lo, hi)) < len(blobs)
    assert 0 < len(imd.cut_field(knot[1], lo, hi).patches["radii"]) < len(knot[1].patches["radii"])
    assert imd.cut_field(blobs, lo + 5, hi + 5) is None


def test_a_partition_cut_ships_only_its_part(knot):
    """A tile's cut of a partition fit pickles to a part of the whole that shrinks with the
    tile (patches, octree and constraints), and evaluates, once unpickled, to the whole's bits
    at the tile's lattice points."""
    import pickle

    surface = knot[1]
    bounds = np.asarray(surface.bounds)
    cells, origin, cell = im._core.lattice(bounds, 40)
    whole = len(pickle.dumps(surface))
    sizes = {}
    for tile in (40, 20, 10):
        sizes[tile] = []
        for lo, hi in imd.tiles(cells, (tile,) * 3):
            part = pickle.loads(pickle.dumps(imd.cut_field(surface, *imd.tile_box(np.asarray(origin), np.asarray(cell), lo, hi))))
            sizes[tile].append(len(pickle.dumps(part)))
            grid = np.stack(np.meshgrid(*[np.arange(a, b + 1) for a, b in zip(lo, hi)], indexing="ij"), -1).reshape(-1, 3)
            points = np.asarray(origin) + grid.astype(np.float64) * np.asarray(cell)
            assert np.array_equal(part(points).view(np.uint64), surface(points).view(np.uint64))
            assert np.array_equal(part.gradient(points).view(np.uint64), surface.gradient(points).view(np.uint64))
            assert 0 < len(part) <= len(surface)
            # A cut of a cut is the same part.
            again = imd.cut_field(part, *imd.tile_box(np.asarray(origin), np.asarray(cell), lo, hi))
            assert np.array_equal(again(points).view(np.uint64), surface(points).view(np.uint64))
    # The whole lattice's cut is the whole plus its octree.
    assert max(sizes[40]) < 1.05 * whole
    assert np.mean(sizes[10]) < 0.7 * whole and np.mean(sizes[10]) < np.mean(sizes[20]) < whole


def test_larger_cuts_of_a_partition_fit_run_first(knot, blobs):
    """A partition fit's tiles get Dask priorities that grow with their cut's constraints, all
    below the weld's writes; blob tiles and shared fields keep window order (priority 0)."""
    from implicitmesh.distributed import _weld_in_place

    surface = knot[1]
    cells, origin, cell = im._core.lattice(np.asarray(surface.bounds), 40)
    parts = [imd.cut_field(surface, *imd.tile_box(np.asarray(origin), np.asarray(cell), lo, hi))
             for lo, hi in imd.tiles(cells, (10,) * 3)]
    sizes = [len(p) for p in parts]
    assert len(set(sizes)) > 5
    priorities = [_plan.tile_priority(p) for p in parts]
    assert all(p < _weld_in_place.WRITE_PRIORITY for p in priorities)
    by_size = sorted(zip(sizes, priorities))
    assert all(a[1] < b[1] for a, b in zip(by_size, by_size[1:]) if a[0] < b[0])
    assert _plan.tile_priority(imd.cut_field(blobs, np.full(3, -0.5), np.full(3, 0.5))) == 0
    assert _plan.tile_priority(knot[0]) == 0


def test_a_cut_file_reads_back_the_cut_bit_for_bit(knot, tmp_path):
    """A partition cut written to a file (how the client hands cuts to workers on its machine)
    loads as the same surface: the same bits at the tile's points, the same state; a process
    that does not see the file gets CutFileMissing, which the client answers by sending the cut
    through Dask."""
    from implicitmesh.distributed import _cut_files

    surface = knot[1]
    lo, hi = np.array([-0.5, -0.2, 0.0]), np.array([0.1, 0.3, 0.4])
    part = imd.cut_field(surface, lo, hi)
    cut = _cut_files.write(str(tmp_path), 3, part)
    assert isinstance(cut, _cut_files.CutFile) and os.path.isfile(cut.path)
    import pickle

    back = pickle.loads(pickle.dumps(cut)).load()
    points = lo + (hi - lo) * np.random.default_rng(4).random((300, 3))
    assert np.array_equal(back(points).view(np.uint64), surface(points).view(np.uint64))
    assert np.array_equal(back.gradient(points).view(np.uint64), part.gradient(points).view(np.uint64))
    a, b = part.to_state(), back.to_state()
    assert a.keys() == b.keys()
    for k in a:
        assert np.array_equal(a[k], b[k]) if isinstance(a[k], np.ndarray) else a[k] == b[k]
    _cut_files.remove(cut)
    assert not os.path.exists(cut.path) and list(tmp_path.iterdir()) == []
    with pytest.raises(_cut_files.CutFileMissing):
        cut.load()
    assert _cut_files.write(str(tmp_path / "missing"), 0, part) is None
    # A blob field's cut, with its kernel, precision and threshold.
    rng = np.random.default_rng(6)
    blobs = im.BlobField.from_particles(rng.uniform(-0.5, 0.5, (400, 3)), 0.05, precision="single")
    part = imd.cut_field(blobs, lo, hi)
    back = _cut_files.write(str(tmp_path), 4, part).load()
    assert isinstance(back, im.BlobField) and len(back) == len(part) < len(blobs)
    assert np.array_equal(back(points).view(np.uint64), blobs(points).view(np.uint64))
    assert np.array_equal(back.gradient(points).view(np.uint64), part.gradient(points).view(np.uint64))
    (a, ka), (b, kb) = part.__getnewargs_ex__(), back.__getnewargs_ex__()
    assert ka == kb and a[3] == b[3] and all(np.array_equal(x, y) for x, y in zip(a[:3], b[:3]))


@pytest.mark.parametrize("kind", ["partition", "blobs", "small-blobs"])
@pytest.mark.parametrize("route", ["files", "files-unseen", "scattered"])
def test_cuts_reach_the_workers_through_files_or_dask(client, knot, blobs, monkeypatch, route, kind):
    """Workers that see the run's directory read each tile's cut from a file there ("files"); a
    worker that does not see its file has the cut sent again through Dask ("files-unseen"), as
    do all tiles when the workers do not see the directory ("scattered"): the single machine's
    mesh each way, and the run's directory removed afterwards. Blob cuts of fewer than
    MIN_SENT_BLOBS primitives travel inside their tasks ("small-blobs")."""
    from implicitmesh.distributed import _cut_files, _tile_files

    field, options = (knot[1], {"method": "octree"}) if kind == "partition" else (blobs, {"bounds": BOX, "method": "sparse"})
    if kind == "blobs":
        monkeypatch.setattr(_transport.SentCuts, "MIN_SENT_BLOBS", 0)
    made, original = [], _tile_files.make_directory

    def make_directory():
        made.append("/nonexistent/implicitmesh-tiles" if route == "scattered" else original())
        return made[-1]

    monkeypatch.setattr(_tile_files, "make_directory", make_directory)
    write, sent = _cut_files.write, []

    def counted_write(directory, tile, part):
        cut = write(directory, tile, part)
        if route == "files-unseen":
            os.remove(cut.path)
            cut = _cut_files.CutFile(os.path.join(directory, "elsewhere", f"cut-{tile}"))
        sent.append(cut)
        return cut

    monkeypatch.setattr(_cut_files, "write", counted_write)
    resent = []
    collect = _run._collect

    def counted_collect(distributed, futures, cuts, resend, weld, report):
        return collect(distributed, futures, cuts, lambda i: resent.append(i) or resend(i), weld, report)

    monkeypatch.setattr(_run, "_collect", counted_collect)
    whole = im.polygonize(field, resolution=40, **options)
    scattered = []
    monkeypatch.setattr(client, "scatter", lambda *a, **k: scattered.append(1) or distributed.Client.scatter(client, *a, **k))
    tiled = imd.polygonize(field, resolution=40, client=client, tile=13, **options)
    assert_same_mesh(tiled, whole)
    tiles = tiled.stats["tiles"]
    inline = kind == "small-blobs"
    assert len(sent) == (0 if route == "scattered" or inline else tiles)
    assert len(scattered) == (0 if inline else tiles if route == "scattered" else 0)
    assert sorted(resent) == (list(range(tiles)) if route == "files-unseen" and not inline else [])
    assert not os.path.exists(made[0])


def test_the_core_cut_refuses_bad_input(blobs):
    with pytest.raises(ValueError, match="index"):
        blobs._subset(np.array([0, len(blobs)], dtype=np.uint32))
    with pytest.raises(ValueError, match="tile"):
        blobs._tile_primitives([0.0, 0.0, 0.0], [0.1, 0.1, 0.1], [4, 4, 4], [2, 0, 2], 1e-6)
    part = blobs._subset(np.array([5, 2], dtype=np.uint32))
    assert np.array_equal(part.centers, blobs.centers[[5, 2]]) and part.threshold == blobs.threshold


def test_tiles_get_the_primitives_cut_blobs_gives_them():
    """The primitives of every tile, found for all tiles at once, are those cut_blobs finds for
    the tile alone (uneven tiles, radii from a tenth of a tile to several tiles, centres outside
    the lattice, and a lattice far from the origin with centres on tile faces and spheres
    ending on them)."""
    rng = np.random.default_rng(8)
    far = np.array([[1e4, -3e3, 7e2], [1e4 + 2.0, -3e3 + 2.0, 7e2 + 2.0]])
    cells, origin, cell = im._core.lattice(far, 16)
    faces = np.asarray(origin) + np.asarray(cell) * rng.integers(0, 5, (200, 3)) * 4
    cases = [
        (rng.uniform(-1.2, 1.2, (800, 3)), rng.uniform(0.01, 0.5, 800), np.asarray(BOX), (37, 20, 11), (6, 20, 4)),
        (faces, np.asarray(cell)[0] * rng.integers(1, 6, 200), far, 16, (4, 4, 4)),
    ]
    for centers, radii, bounds, resolution, tile in cases:
        field = im.BlobField(centers, radii, kernel="wendland")
        cells, origin, cell = im._core.lattice(bounds, resolution)
        origin, cell = np.asarray(origin), np.asarray(cell)
        parts = _plan.blob_tiles(field, cells, origin, cell, tile)
        windows = list(imd.tiles(cells, tile))
        assert len(parts) == len(windows) > 1
        assert any(p is not None for p in parts)
        for (lo, hi), part in zip(windows, parts):
            alone = imd.cut_blobs(field, *imd.tile_box(origin, cell, lo, hi))
            assert (part is None) == (alone is None)
            if part is not None:
                assert part.kernel == "wendland"
                for name in ("centers", "radii", "strengths"):
                    assert np.array_equal(getattr(part, name), getattr(alone, name))


def test_callable_and_uneven_tiles(client):
    sphere = lambda p: np.linalg.norm(p - 0.05, axis=1) - 0.7  # noqa: E731
    whole = im.polygonize(sphere, bounds=[[-1, -1, -1], [1, 0.9, 0.8]], resolution=(23, 19, 17))
    for tile in (7, (5, 19, 4), 100):
        tiled = imd.polygonize(sphere, bounds=[[-1, -1, -1], [1, 0.9, 0.8]], resolution=(23, 19, 17), method="dense", client=client, tile=tile)
        assert_same_mesh(tiled, whole)
        assert genus_of(tiled.euler_number) == 0


def test_options_reach_every_tile(client, blobs):
    whole = im.polygonize(blobs, bounds=BOX, resolution=24, method="dense", ambiguity="join", normals=False)
    tiled = imd.polygonize(blobs, bounds=BOX, resolution=24, method="dense", client=client, tile=7, ambiguity=im.Ambiguity.JOIN, normals=False)
    assert len(tiled.normals) == 0
    assert np.array_equal(triangles(tiled), triangles(whole)) and len(tiled.vertices) == len(whole.vertices)


def test_zeros_on_tile_faces(client):
    """The field is exactly zero at lattice points on tile faces, along tile edges and at tile
    corners, where several edges give one position and so several vertices (up to six for the
    octahedron's corners): one machine keeps one vertex per edge, and so does the weld, which
    joins vertices by their lattice edge."""
    diagonal = lambda p: p[:, 0] + p[:, 1] - 0.5  # noqa: E731
    octahedron = lambda p: np.abs(p).sum(axis=1) - 0.75  # noqa: E731
    for field, tiles in (
        (diagonal, [(16, 16, 3), (4, 2, 5), 3]),
        (octahedron, [(16, 16, 3), (2, 16, 16), 3, 2, (5, 3, 4)]),
    ):
        for method in ("dense", "octree"):
            whole = im.polygonize(field, bounds=BOX, resolution=16, method=method)
            assert len(np.unique(whole.vertices, axis=0)) < len(whole.vertices)
            for tile in tiles:
                tiled = imd.polygonize(field, bounds=BOX, resolution=16, method=method, client=client, tile=tile)
                assert_same_mesh(tiled, whole)
    # 80 positions of the octahedron hold three vertices each (366 vertices at 146 positions),
    # on one machine and welded.
    whole = im.polygonize(octahedron, bounds=BOX, resolution=16, method="dense")
    tiled = imd.polygonize(octahedron, bounds=BOX, resolution=16, method="dense", client=client, tile=3)
    for mesh in (whole, tiled):
        counts = np.unique(mesh.vertices, axis=0, return_counts=True)[1]
        assert np.bincount(counts).tolist() == [0, 6, 60, 80]


def _edge_ends(keys: np.ndarray, origin, cell) -> tuple[np.ndarray, np.ndarray]:
    """The two lattice points (positions as the core computes them) of each edge key."""
    p = keys >> np.uint64(2)
    lo = np.stack([(p >> np.uint64(20 * a)) & np.uint64(2**20 - 1) for a in range(3)], axis=1).astype(np.int64)
    hi = lo.copy()
    hi[np.arange(len(keys)), (keys & np.uint64(3)).astype(np.int64)] += 1
    return np.asarray(origin) + lo * np.asarray(cell), np.asarray(origin) + hi * np.asarray(cell)


@pytest.mark.parametrize("method", ["dense", "sparse", "octree", "tracking"])
def test_boundary_keys_name_each_vertex_edge(blobs, method):
    """With boundary=True a window's run lists its vertices on edges in its boundary faces, each
    once, with the key of an edge of the window in that boundary that holds the vertex."""
    cells, origin, cell = im._core.lattice(BOX, 32)
    window = [[8, 5, 0], [20, 32, 13]]
    v, f, n, stats, b, k = im._core.polygonize(blobs, BOX, 32, method=method, window=window, boundary=True)
    assert b.dtype == np.uint32 and k.dtype == np.uint64 and len(b) == len(k) > 0
    assert len(np.unique(b)) == len(b) and len(np.unique(k)) == len(k)
    a, c = _edge_ends(k, origin, cell)
    p = v[b]
    assert np.all((np.minimum(a, c) <= p) & (p <= np.maximum(a, c)))
    axis = (k & np.uint64(3)).astype(np.int64)
    lo = np.asarray(origin) + np.asarray(window[0]) * np.asarray(cell)
    hi = np.asarray(origin) + np.asarray(window[1]) * np.asarray(cell)
    on_face = (a == lo) | (a == hi)
    on_face[np.arange(len(k)), axis] = False
    assert on_face.any(axis=1).all()
    # The listed vertices lie on the boundary, and those on it not listed at lattice points
    # (on edges that leave the boundary into the window).
    face = ((v == lo) | (v == hi)).any(axis=1)
    assert face[b].all()
    rest = v[np.setdiff1d(np.flatnonzero(face), b)]
    assert np.array_equal(np.asarray(origin) + np.round((rest - origin) / cell) * np.asarray(cell), rest)
    same = im._core.polygonize(blobs, BOX, 32, method=method, window=window)
    assert np.array_equal(same[0], v) and np.array_equal(same[1], f)


def test_tiles_of_one_cell(client, blobs):
    small = im.BlobField(blobs.centers[:3] * 0.5, 0.4)
    whole = im.polygonize(small, bounds=[[-0.7] * 3, [0.7] * 3], resolution=9, method="dense")
    tiled = imd.polygonize(small, bounds=[[-0.7] * 3, [0.7] * 3], resolution=9, method="sparse", client=client, tile=1)
    assert_same_mesh(tiled, whole)
    assert tiled.stats["tiles"] <= 9**3


def test_output_directory_and_weld(client, blobs, tmp_path):
    whole = im.polygonize(blobs, bounds=BOX, resolution=40, method="sparse")
    out = imd.write_tiles(blobs, tmp_path / "run", bounds=BOX, resolution=40, client=client, tile=15)
    assert out == tmp_path / "run"
    files = sorted(p.name for p in out.iterdir())
    assert "manifest.json" in files and any(f.endswith(".npz") for f in files)
    assert not any(f.endswith(".part") for f in files)
    done = []
    assert_same_mesh(imd.weld(out, progress=done.append), whole)
    manifest = json.loads((out / "manifest.json").read_text())
    assert done[-1] == sum(e["vertices"] for e in manifest["tiles"]) > len(whole.vertices)
    with pytest.raises(ValueError, match="directory"):
        imd.weld(tmp_path)
    # A tile without edge keys (an older run's) is refused, naming the directory.
    first = manifest["tiles"][0]["file"]
    with np.load(out / first) as z:
        arrays = {k: z[k] for k in ("vertices", "faces", "normals")}
    np.savez(out / first, **arrays)
    with pytest.raises(ValueError, match="directory: .*edge keys"):
        imd.weld(out)


@pytest.mark.parametrize("case", ["blobs", "octahedron"])
def test_gathered_tiles_weld_as_the_core_welds_them(client, blobs, tmp_path, case):
    """The gathered run (tiles welded in window order as they arrive, whatever order they
    finish in) and weld(DIR) (tiles read one at a time) give the arrays the core's weld makes
    of all the tiles at once, bit for bit and in the same order, also where several vertices
    share a position on tile faces."""
    if case == "blobs":
        field, kw = blobs, {"bounds": BOX, "resolution": 40, "method": "sparse", "tile": 15}
    else:
        field, kw = (lambda p: np.abs(p).sum(axis=1) - 0.75), {"bounds": BOX, "resolution": 16, "method": "dense", "tile": 3}
    gathered = imd.polygonize(field, client=client, **kw)
    out = imd.write_tiles(field, tmp_path / "run", client=client, **kw)
    welded = imd.weld(out)
    manifest = json.loads((out / "manifest.json").read_text())
    tiles = []
    for e in manifest["tiles"]:
        with np.load(out / e["file"]) as z:
            tiles.append((e["window"], *(z[a] for a in ("vertices", "faces", "normals", "boundary", "keys"))))
    core = im._core.weld_tiles(tiles, manifest["cells"], manifest["origin"], manifest["cell"])
    for mesh in (gathered, welded):
        for a, b in zip((mesh.vertices, mesh.faces, mesh.normals), core):
            assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a.view(np.uint64), b.view(np.uint64))
    assert gathered.stats == welded.stats
    assert_same_mesh(gathered, im.polygonize(field, **{k: v for k, v in kw.items() if k != "tile"}))


def test_the_streamed_weld_checks_its_tiles():
    from implicitmesh._core import StreamedWeld

    lattice = ([4, 4, 4], [0.0, 0.0, 0.0], [0.25, 0.25, 0.25])
    w = [[0, 0, 0], [4, 4, 4]]
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    none = (np.zeros(0, np.uint32), np.zeros(0, np.uint64))
    with pytest.raises(ValueError, match="faces"):
        StreamedWeld(1, *lattice, False).add(w, v, np.array([[0, 1, 3]], np.uint32), np.zeros((0, 3)), *none)
    with pytest.raises(ValueError, match="normals"):
        StreamedWeld(1, *lattice, True).add(w, v, np.array([[0, 1, 2]], np.uint32), v[:1], *none)
    with pytest.raises(ValueError, match="window"):
        StreamedWeld(1, *lattice).add([[0, 0, 0], [5, 4, 4]], v, np.array([[0, 1, 2]], np.uint32), v, *none)
    with pytest.raises(ValueError, match="cells"):
        StreamedWeld(1, [0, 4, 4], *lattice[1:])
    # One edge at two positions in two tiles; the refused tile leaves the weld as it was.
    weld = StreamedWeld(2, *lattice, False)
    one = (np.array([0], np.uint32), np.array([0], np.uint64))
    weld.add(w, v, np.array([[0, 1, 2]], np.uint32), np.zeros((0, 3)), *one)
    with pytest.raises(ValueError, match="tiles"):
        weld.add(w, v + 0.5, np.array([[0, 1, 2]], np.uint32), np.zeros((0, 3)), *one)
    assert (weld.added, weld.vertices) == (1, 3)
    # Joined by key, the second tile's first vertex is the first tile's; more rows than the
    # estimate grow the arrays.
    weld = StreamedWeld(1, *lattice, True)
    for shift in (0.0, 1.0):
        weld.add(w, v + [shift, 0, 0] * (np.arange(3) > 0)[:, None], np.array([[0, 1, 2]], np.uint32), v, *one)
    out_v, out_f, out_n = weld.result()
    assert len(out_v) == len(out_n) == 5 and out_f.tolist() == [[0, 1, 2], [0, 3, 4]] and out_f.dtype == np.int64
    with pytest.raises(RuntimeError, match="result"):
        weld.result()
    # normals=None: as the first tile with vertices has them (an empty tile first); a later
    # tile without them is refused.
    empty = (np.zeros((0, 3)), np.zeros((0, 3), np.uint32), np.zeros((0, 3)), *none)
    for normals, expected in ((v, 3), (np.zeros((0, 3)), 0)):
        weld = StreamedWeld(2, *lattice)
        weld.add(w, *empty)
        weld.add(w, v, np.array([[0, 1, 2]], np.uint32), normals, *none)
        assert weld.result()[2].shape == (expected, 3)
    weld = StreamedWeld(2, *lattice)
    weld.add(w, v, np.array([[0, 1, 2]], np.uint32), v, *none)
    with pytest.raises(ValueError, match="normals"):
        weld.add(w, v, np.array([[0, 1, 2]], np.uint32), np.zeros((0, 3)), *none)


def test_the_weld_checks_its_tiles():
    from implicitmesh import _core

    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    tile = lambda faces, normals=np.zeros((0, 3)), window=((0, 0, 0), (4, 4, 4)): (window, v, faces, normals)  # noqa: E731
    lattice = ([4, 4, 4], [0.0, 0.0, 0.0], [0.25, 0.25, 0.25])
    none = (np.zeros(0, np.uint32), np.zeros(0, np.uint64))
    for bad, name in (
        (tile([[0, 1, 3]]), "faces"), (tile([[0, 1, 2]], v[:1]), "normals"),
        (tile([[0, 1, 2]], window=((0, 0, 0), (5, 4, 4))), "window"), (tile([0, 1, 2]), "faces"),
        (tile([[0, 1, 2]])[:4] + ([0, 1], [0]), "keys"), (tile([[0, 1, 2]])[:4] + ([7], [0]), "boundary"),
        (tile([[0, 1, 2]])[:4] + ([[0]], [0]), "boundary"), (tile([[0, 1, 2]])[:4] + ([0], [20]), "keys"),
        (tile([[0, 1, 2]])[:4] + ([0, 1], [0, 0]), "keys"), (tile([[0, 1, 2]])[:4], "tiles"),
    ):
        bad = bad + none if len(bad) == 4 and name != "tiles" else bad
        with pytest.raises(ValueError, match=name):
            _core.weld_tiles([bad], *lattice)
    # One edge at two positions in two tiles: not the tiles of one field and lattice.
    moved = (tile([[0, 1, 2]])[0], v + 0.5, [[0, 1, 2]], np.zeros((0, 3)), [0], [0])
    with pytest.raises(ValueError, match="tiles"):
        _core.weld_tiles([tile([[0, 1, 2]]) + ([0], [0]), moved], *lattice)
    # Any layout of the arrays is read: strided, Fortran-ordered, int32 and float32.
    grid = np.asfortranarray(np.repeat(v, 2, axis=0)[::2])
    out = _core.weld_tiles([(tile([[0, 1, 2]])[0], grid, np.array([[0, 1, 2]], dtype=np.int32), np.zeros((0, 3), np.float32), *none)], *lattice)
    assert np.array_equal(out[0], v) and np.array_equal(out[1], [[0, 1, 2]]) and out[2].shape == (0, 3)


def test_empty_result_and_progress(client, blobs):
    seen = []
    far = im.BlobField([[5.0, 5.0, 5.0]], 0.3)
    mesh = imd.polygonize(far, bounds=BOX, resolution=16, client=client, tile=8, progress=seen.append)
    assert len(mesh.faces) == 0 and len(mesh.vertices) == 0 and mesh.stats["tiles"] == 0
    imd.polygonize(blobs, bounds=BOX, resolution=16, client=client, tile=8, progress=seen.append)
    assert seen and seen[-1] == 8 and seen == sorted(seen)


def test_tiles_fit_where_the_whole_lattice_does_not(client):
    """512³: the whole lattice's dense values (1.08 GB) exceed each worker's memory limit, and
    its memory estimate exceeds memory_limit, which every tile of 256³ meets."""
    sphere = im.BlobField([[0.0, 0.0, 0.0], [0.2, 0.1, 0.0]], 0.5)
    limit = 150 * 2**20
    with pytest.raises(ValueError, match="resolution"):
        im.polygonize(sphere, bounds=BOX, resolution=512, method="dense", memory_limit=limit, normals=False)
    mesh = imd.polygonize(sphere, bounds=BOX, resolution=512, method="sparse", client=client, memory_limit=limit, normals=False)
    assert 513**3 * 8 > WORKER_MEMORY
    assert mesh.stats["tiles"] == 8
    assert mesh.to_trimesh().is_watertight and genus_of(mesh.euler_number) == 0


@pytest.mark.parametrize("weld_in", ["client", "place"])
def test_a_welded_mesh_over_memory_limit_is_refused(client, blobs, tmp_path, monkeypatch, weld_in):
    """Tiles each well within memory_limit whose welded mesh is not: the gathered run (welded
    in the client or in place) raises a ValueError naming memory_limit and cancels every task;
    weld(DIR) of the same tiles too; with the limit raised to the mesh's bytes, both give the
    one-machine mesh."""
    from implicitmesh.distributed import _weld_in_place

    monkeypatch.setattr(_weld_in_place, "MIN_TILE_CELLS", 0 if weld_in == "place" else 1 << 62)
    monkeypatch.setattr(_run, "_worker_threads", lambda client: 1 << 20)
    whole = im.polygonize(blobs, bounds=BOX, resolution=96, method="sparse")
    need = whole.vertices.nbytes + whole.normals.nbytes + whole.faces.nbytes
    limit = need // 3
    with pytest.raises(ValueError, match=r"memory_limit: the welded mesh .*\(output=DIR\)"):
        imd.polygonize(blobs, bounds=BOX, resolution=96, client=client, tile=16, memory_limit=limit)
    assert tasks_left(client) == 0
    out = imd.write_tiles(blobs, tmp_path / "run", bounds=BOX, resolution=96, client=client, tile=16,
                          memory_limit=limit)
    with pytest.raises(ValueError, match="memory_limit"):
        imd.weld(out, memory_limit=limit)
    for bad in (0, -1, 2.5, True):
        with pytest.raises(ValueError, match="memory_limit"):
            imd.weld(out, memory_limit=bad)
    assert_same_mesh(imd.weld(out, memory_limit=need), whole)
    assert_same_mesh(imd.polygonize(blobs, bounds=BOX, resolution=96, client=client, tile=16, memory_limit=need), whole)


def test_bad_arguments(client, blobs):
    for tile in (0, -3, 2.5, True, (4, 4), "8"):
        with pytest.raises(ValueError, match="tile"):
            imd.polygonize(blobs, bounds=BOX, resolution=8, client=client, tile=tile)
    for method in ("marching", 3):
        with pytest.raises(ValueError, match="method"):
            imd.polygonize(blobs, bounds=BOX, resolution=8, client=client, method=method)
    for method in ("sparse", "tracking"):
        with pytest.raises(ValueError, match="method"):
            imd.polygonize(lambda p: p[:, 0], bounds=BOX, resolution=8, client=client, method=method)
    with pytest.raises(ValueError, match="resolution"):
        imd.polygonize(blobs, bounds=BOX, resolution=0, client=client)
    with pytest.raises(ValueError, match="window"):
        im._core.polygonize(blobs, BOX, 8, window=[[0, 0, 0], [9, 1, 1]])
    with pytest.raises(TypeError, match="seeds"):
        imd.polygonize(blobs, bounds=BOX, resolution=8, client=client, seeds=[[0, 0, 0]])
    with pytest.raises(TypeError, match="field"):
        imd.polygonize(object(), bounds=BOX, resolution=8, client=client, method="dense")
    lock = threading.Lock()
    with pytest.raises(TypeError, match="field: .*pickle"):
        imd.polygonize(lambda p: p[:, 0] + 0 * bool(lock), bounds=BOX, resolution=8, client=client, method="dense")


def test_without_dask_the_error_names_the_extra(monkeypatch, blobs):
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(ImportError, match=r"implicitmesh\[distributed\]"):
        imd.polygonize(blobs, bounds=BOX, resolution=8)


def tasks_left(client, wait: float = 15.0) -> int:
    """The tasks the scheduler still holds, once it holds none or after ``wait`` seconds."""
    left = client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks))
    end = time.monotonic() + wait
    while left and time.monotonic() < end:
        time.sleep(0.1)
        left = client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks))
    return left


def test_ctrl_c_cancels_the_tasks(client, knot):
    def interrupt(done: int) -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        imd.polygonize(knot[0], resolution=40, method="dense", client=client, tile=10, progress=interrupt)
    assert tasks_left(client) == 0


@pytest.mark.parametrize("weld_in", ["client", "place"])
def test_ctrl_c_during_the_weld_cancels_the_tasks(client, blobs, monkeypatch, weld_in):
    """A Ctrl-C (SIGINT to the main thread) while the client welds the first tile that arrived
    (in the client or in place) raises KeyboardInterrupt and cancels the tasks not done; the
    next run is whole."""
    import _thread

    from implicitmesh.distributed import _weld_in_place

    monkeypatch.setattr(_weld_in_place, "MIN_TILE_CELLS", 0 if weld_in == "place" else 1 << 62)
    monkeypatch.setattr(_run, "_worker_threads", lambda client: 1 << 20)

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    add = _run.weld_tile
    welds = []

    def interrupted_add(weld, entry, tile):
        welds.append(tile)
        _thread.interrupt_main()
        add(weld, entry, tile)
        time.sleep(1.0)  # the signal is handled here at the latest

    monkeypatch.setattr(_run, "weld_tile", interrupted_add)
    try:
        with pytest.raises(KeyboardInterrupt):
            imd.polygonize(blobs, bounds=BOX, resolution=96, method="dense", client=client, tile=8, memory_limit=1 << 28)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert len(welds) == 1
    assert tasks_left(client) == 0
    monkeypatch.setattr(_run, "weld_tile", add)
    whole = im.polygonize(blobs, bounds=BOX, resolution=24, method="sparse")
    assert_same_mesh(imd.polygonize(blobs, bounds=BOX, resolution=24, client=client, tile=8), whole)


def test_the_current_client_is_the_default(client, blobs):
    assert distributed.get_client() is client
    whole = im.polygonize(blobs, bounds=BOX, resolution=16, method="sparse")
    assert_same_mesh(imd.polygonize(blobs, bounds=BOX, resolution=16, tile=7), whole)


@pytest.mark.parametrize("cuts", ["files", "scattered"])
def test_a_worker_killed_mid_run_changes_nothing(client, knot, monkeypatch, cuts):
    """One worker process is killed when the first tile is done; Dask recomputes its tasks on
    the worker left and on the one its nanny restarts, from the cuts' files, or, for cuts
    scattered to the killed worker (workers that do not see the run's directory), from the
    cuts the client sends again."""
    if cuts == "scattered":
        from implicitmesh.distributed import _tile_files

        monkeypatch.setattr(_tile_files, "make_directory", lambda: None)
    surface = knot[1]
    whole = im.polygonize(surface, resolution=40, method="dense")
    pids = client.run(os.getpid)
    killed = []

    def kill_one(done: int) -> None:
        if not killed:
            pid = next(iter(pids.values()))
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    resent = []
    collect = _run._collect

    def counted_collect(distributed, futures, sent, resend, weld, report):
        return collect(distributed, futures, sent, lambda i: resent.append(i) or resend(i), weld, report)

    monkeypatch.setattr(_run, "_collect", counted_collect)
    tiled = imd.polygonize(surface, resolution=40, method="dense", client=client, tile=8, progress=kill_one)
    assert killed
    assert_same_mesh(tiled, whole)
    # Files outlive the worker: no cut is sent again. Scattered cuts die with it.
    assert (len(resent) > 0) == (cuts == "scattered")


@pytest.mark.parametrize("transport", ["in-place", "in-place-whole", "files", "comms", "files-unseen"])
def test_tiles_reach_the_client_in_place_through_files_or_dask(client, blobs, monkeypatch, transport):
    """Workers on the client's machine write their tiles (here of any size) into the welded
    mesh's files in the run's directory ("in-place"; tiles under MIN_KEPT_BYTES come back whole from
    their one task and the client writes them, "in-place-whole"), or, where it cannot hold the welded mesh,
    pass them through files there ("files"); without one ("comms"), or where the workers do
    not see it ("files-unseen"), the tiles come through Dask: the same arrays each way, bit for
    bit, and the directory removed afterwards."""
    from implicitmesh.distributed import _tile_files, _weld_in_place

    made, original = [], _tile_files.make_directory

    def make_directory():
        d = {"in-place": original, "in-place-whole": original, "files": original, "comms": lambda: None,
             "files-unseen": lambda: "/nonexistent/implicitmesh-tiles"}[transport]()
        made.append(d)
        return d

    monkeypatch.setattr(_tile_files, "make_directory", make_directory)
    in_place = transport.startswith("in-place")
    monkeypatch.setattr(_tile_files, "MIN_BYTES", 0)
    monkeypatch.setattr(_weld_in_place, "MIN_KEPT_BYTES", 1 << 40 if transport == "in-place-whole" else 0)
    monkeypatch.setattr(_weld_in_place, "MIN_TILE_CELLS", 0 if in_place else 1 << 62)
    monkeypatch.setattr(_run, "_worker_threads", lambda client: 1 << 20)
    read, write_rows, gathered = _tile_files.read, _weld_in_place.write_rows, _run.gathered_weld
    files_read, client_writes = [], []

    def counted_read(directory, name):
        files_read.append(name)
        return read(directory, name)

    def counted_write_rows(*args):
        client_writes.append(len(args[1]))
        return write_rows(*args)

    monkeypatch.setattr(_tile_files, "read", counted_read)
    monkeypatch.setattr(_weld_in_place, "write_rows", counted_write_rows)
    welds_in_place, entry_tasks, entry_task = [], [], _weld_in_place.WeldInPlace.entry_task
    monkeypatch.setattr(_run, "gathered_weld", lambda *a: welds_in_place.append(a[2] is not None) or gathered(*a))

    def counted_entry_task(self, i, fut):
        follow = entry_task(self, i, fut)
        if follow is not None:
            entry_tasks.append(i)
        return follow

    monkeypatch.setattr(_weld_in_place.WeldInPlace, "entry_task", counted_entry_task)
    whole = im.polygonize(blobs, bounds=BOX, resolution=40, method="sparse")
    # A memory limit of 64 MiB: the welded mesh fits in a small /dev/shm too.
    tiled = imd.polygonize(blobs, bounds=BOX, resolution=40, method="sparse", client=client, tile=15, memory_limit=1 << 26)
    assert welds_in_place == [in_place]
    assert_same_mesh(tiled, whole)
    assert len(files_read) == (tiled.stats["tiles"] if transport == "files" else 0)
    # In place, every tile is written by a worker (none is under MIN_KEPT_BYTES), after a task
    # gives its entry; or every tile comes back whole and the client writes it.
    tiles = tiled.stats["tiles"]
    assert len(client_writes) == (tiles if transport == "in-place-whole" else 0)
    assert len(entry_tasks) == (tiles if transport == "in-place" else 0)
    if made[0] is not None:
        assert not os.path.exists(made[0])
    if in_place:
        monkeypatch.setattr(_weld_in_place, "MIN_TILE_CELLS", 1 << 62)
        streamed = imd.polygonize(blobs, bounds=BOX, resolution=40, method="sparse", client=client, tile=15,
                                  memory_limit=1 << 26)
        for a, b in ((tiled.vertices, streamed.vertices), (tiled.faces, streamed.faces), (tiled.normals, streamed.normals)):
            assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a.view(np.uint64), b.view(np.uint64))
        assert tiled.vertices.flags.writeable and tiled.stats == streamed.stats


class _SyncClient:
    """A stand-in for a Dask client that runs each task at once; tiles written by ``write_kept``
    come back as rows, as from a worker on another machine."""

    class Future:
        def __init__(self, value):
            self.value = value

        def done(self):
            return True

        def result(self):
            return self.value

        def release(self):
            self.value = None

    def submit(self, fn, *args, **kwargs):
        from implicitmesh.distributed import _weld_in_place

        args = [a.value if isinstance(a, self.Future) else a for a in args]
        if fn is _weld_in_place.write_kept:
            m = args[0].mesh
            return self.Future((m.vertices, m.faces, m.normals))
        return self.Future(fn(*args))

    def gather(self, futures):
        return [f.result() for f in futures]


def test_a_weld_in_place_writes_the_rows_a_worker_elsewhere_returns(blobs, tmp_path):
    """Tiles whose workers cannot write the welded files (another machine) return their rows,
    which the client writes: the arrays of the weld in the client's memory, bit for bit."""
    from implicitmesh.distributed import _weld_in_place

    cells, origin, cell = im._core.lattice(np.asarray(BOX, float), 30)
    fake, kept = _SyncClient(), {}
    weld = _weld_in_place.WeldInPlace(fake, str(tmp_path), kept, cells, origin, cell, True, None)
    stream = im._core.StreamedWeld(0, cells, origin, cell, True)
    options = dict(ambiguity="separate", normals=True, batch_size=262144, memory_limit=None)
    for i, (lo, hi) in enumerate(imd.tiles(cells, (11, 11, 11))):
        # Every other tile comes back whole, and the client writes it.
        keep = _transport.Transport.keep(0 if i % 2 else 1 << 40)
        kept[i] = fake.submit(_tile.run_tile, blobs, BOX, 30, (lo, hi), "dense", options, keep)
        value = kept[i].value
        assert isinstance(value, _tile.TileResult) == (i % 2 == 0)
        result = _weld_in_place.tile_entry(value)
        assert isinstance(result, _tile.TileResult) and result.kept == (i % 2 == 1)
        m = value.mesh
        assert (result.mesh is None) == result.kept and result.vertices == len(m.vertices)
        stream.add([list(lo), list(hi)], *m.weld_arrays())
        weld.add(result, i)
    assert not kept
    for a, b in zip(weld.result(), stream.result()):
        assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a.view(np.uint64), b.view(np.uint64))
    # A worker that does not see the files, or cannot open them, returns the rows.
    kept_tile = _tile.run_tile(blobs, BOX, 30, ((0, 0, 0), (11, 11, 11)), "dense", options, _transport.Transport.keep(0))
    assert isinstance(kept_tile, _tile.KeptTile)
    for where in (tmp_path / "elsewhere", tmp_path):
        paths = {k: str(where / f"absent-{k}") for k in ("vertices", "faces", "normals")}
        rows = _weld_in_place.write_kept(kept_tile, paths, 0, 0, np.zeros((0, 2), np.uint32))
        assert rows is not None and rows[0] is kept_tile.mesh.vertices and rows[1] is kept_tile.mesh.faces


def test_tile_files_read_back_exactly_and_are_removed(tmp_path):
    from implicitmesh.distributed import _tile_files

    rng = np.random.default_rng(3)
    mesh = _tile.TileMesh(vertices=rng.random((7, 3)), faces=rng.integers(0, 7, (9, 3), dtype=np.uint32),
                          normals=rng.random((7, 3)), boundary=np.arange(5, dtype=np.uint32),
                          keys=rng.integers(0, 2**60, 5, dtype=np.uint64))
    empty = _tile.TileMesh(*(a[:0] for a in mesh.weld_arrays()))
    for name, tile in (("full", mesh), ("empty", empty)):
        assert _tile_files.write(str(tmp_path), name, tile.file_arrays())
        with _tile_files.read(str(tmp_path), name) as arrays:
            back = _tile.TileMesh.from_file_arrays(arrays)
            for a, b in zip(tile.weld_arrays(), back.weld_arrays()):
                assert b.dtype == a.dtype and b.shape == a.shape and np.array_equal(b, a)
                assert a.size == 0 or (not b.flags.writeable and b.ctypes.data % a.itemsize == 0)
        assert not (tmp_path / name).exists()
    assert not _tile_files.write(str(tmp_path / "missing"), "x", mesh.file_arrays())
    assert list(tmp_path.iterdir()) == []
    # A run directory whose client has ended is removed; a running client's is kept.
    import subprocess
    import sys

    ended = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    orphan = tmp_path / f"{_tile_files.PREFIX}{int(ended.stdout)}-abc"
    alive = tmp_path / f"{_tile_files.PREFIX}{os.getpid()}-abc"
    for d in (orphan, alive):
        d.mkdir()
        (d / "tile-0-0-0").write_bytes(b"x")
    _tile_files.remove_orphans(str(tmp_path))
    assert sorted(p.name for p in tmp_path.iterdir()) == [alive.name]


def test_one_call_shape_with_implicitmesh_polygonize(client, blobs, knot, tmp_path):
    """distributed.polygonize takes implicitmesh.polygonize's keywords (its defaults but
    method="sparse"); per-method options come flat or as OctreeOptions, checked before any
    task; output=DIR still works, deprecated, as write_tiles."""
    import inspect

    ours, theirs = inspect.signature(imd.polygonize).parameters, inspect.signature(im.polygonize).parameters
    for name, p in theirs.items():
        assert name in ours and ours[name].kind == p.kind
        if name != "method":
            assert ours[name].default == p.default, name
    assert ours["method"].default == "sparse"
    # The stray-fragment option acts on the welded mesh as on one machine's.
    big = max(len(blobs.centers) // 4, 2)
    one = im.polygonize(blobs, bounds=BOX, resolution=24, method="sparse", min_particles=big)
    assert_same_mesh(imd.polygonize(blobs, bounds=BOX, resolution=24, client=client, tile=8, min_particles=big), one)
    assert one.stats["fragments_dropped"] == imd.polygonize(
        blobs, bounds=BOX, resolution=24, client=client, tile=8, min_particles=big).stats["fragments_dropped"]
    surface = knot[1]
    flat = imd.polygonize(surface, resolution=32, method="octree", safety=2.0, client=client, tile=11)
    boxed = imd.polygonize(surface, resolution=32, method="octree", options=im.OctreeOptions(safety=2.0), client=client, tile=11)
    assert_same_mesh(boxed, flat)
    assert_same_mesh(flat, im.polygonize(surface, resolution=32, method="octree", safety=2.0))
    for kw in ({"method": "dense", "safety": 2.0}, {"method": "dense", "options": im.OctreeOptions()},
               {"method": "octree", "options": im.TrackingOptions()}):
        with pytest.raises(ValueError, match="safety|options"):
            imd.polygonize(surface, resolution=16, client=client, tile=8, **kw)
    assert tasks_left(client) == 0
    with pytest.warns(DeprecationWarning, match="write_tiles"):
        out = imd.polygonize(blobs, bounds=BOX, resolution=24, client=client, tile=8, output=tmp_path / "old")
    assert out == tmp_path / "old"
    assert_same_mesh(imd.weld(out), imd.polygonize(blobs, bounds=BOX, resolution=24, client=client, tile=8))
    with pytest.raises(ValueError, match="directory"):
        imd.write_tiles(blobs, tmp_path / "old" / "manifest.json", bounds=BOX, resolution=24, client=client)
