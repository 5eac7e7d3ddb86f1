"""Particle frames from files (:func:`implicitmesh.read_particles`) and the ``particles`` command."""

from __future__ import annotations

import builtins
import importlib.util
import sys

import numpy as np
import pytest
import trimesh

import implicitmesh as im
from implicitmesh.cli import main


def frame(n=500, dtype=np.float64, seed=3):
    return np.random.default_rng(seed).uniform(-1.0, 1.0, (n, 3)).astype(dtype)


def write_ply(path, columns: dict, fmt="binary_little_endian", types=None):
    """A PLY file with one vertex element holding ``columns`` (name to (N,) array) in order."""
    names = list(columns)
    n = len(columns[names[0]])
    types = types or {k: {"f4": "float", "f8": "double", "i4": "int"}[np.dtype(v.dtype).str[1:]] for k, v in columns.items()}
    header = f"ply\nformat {fmt} 1.0\ncomment written by test_frames\nelement vertex {n}\n"
    header += "".join(f"property {types[k]} {k}\n" for k in names) + "end_header\n"
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        if fmt == "ascii":
            for i in range(n):
                f.write((" ".join(repr(columns[k][i].item()) for k in names) + "\n").encode("ascii"))
        else:
            order = "<" if fmt == "binary_little_endian" else ">"
            dt = np.dtype([(k, order + np.dtype(columns[k].dtype).str[1:]) for k in names])
            table = np.empty(n, dtype=dt)
            for k in names:
                table[k] = columns[k]
            f.write(table.tobytes())


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_npy_reads_back_exactly_as_stored(tmp_path, dtype):
    p = frame(dtype=dtype)
    np.save(tmp_path / "f.npy", p)
    q = im.read_particles(tmp_path / "f.npy")
    assert q.dtype == dtype and q.shape == p.shape
    np.testing.assert_array_equal(q, p)
    # Fortran order stays as it is (BlobField reads it without a copy).
    np.save(tmp_path / "g.npy", np.asfortranarray(p))
    g = im.read_particles(str(tmp_path / "g.npy"))
    assert g.flags.f_contiguous and g.dtype == dtype
    np.testing.assert_array_equal(g, p)


def test_npy_structured_and_integer(tmp_path):
    p = frame(40)
    table = np.zeros(40, dtype=[("x", "f8"), ("y", "f8"), ("z", "f8")])
    for k, c in enumerate("xyz"):
        table[c] = p[:, k]
    np.save(tmp_path / "s.npy", table)
    np.testing.assert_array_equal(im.read_particles(tmp_path / "s.npy"), p)
    np.save(tmp_path / "i.npy", np.arange(12, dtype=np.int32).reshape(4, 3))
    q = im.read_particles(tmp_path / "i.npy")
    assert q.dtype == np.float64
    np.testing.assert_array_equal(q, np.arange(12).reshape(4, 3))


def test_npz_key_choice_and_attributes(tmp_path):
    p, r, rho = frame(60, np.float32), np.full(60, 0.01), np.linspace(990, 1010, 60)
    np.savez(tmp_path / "one.npz", p)
    np.testing.assert_array_equal(im.read_particles(tmp_path / "one.npz"), p)
    np.savez(tmp_path / "named.npz", velocity=p[::-1].copy(), points=p, radius=r, density=rho, time=np.float64(0.5))
    q, attrs = im.read_particles(tmp_path / "named.npz", attributes=("radius", "density"))
    assert q.dtype == np.float32
    np.testing.assert_array_equal(q, p)
    np.testing.assert_array_equal(attrs["radius"], r)
    np.testing.assert_array_equal(attrs["density"], rho)
    np.testing.assert_array_equal(im.read_particles(tmp_path / "named.npz", key="velocity"), p[::-1])
    # "positions" comes before "points".
    np.savez(tmp_path / "both.npz", points=p, positions=p[:10])
    assert len(im.read_particles(tmp_path / "both.npz")) == 10


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_ply_reads_back_exactly(tmp_path, fmt, dtype):
    p = frame(80, dtype)
    radius = np.linspace(0.5, 1.5, 80).astype(np.float32)
    ids = np.arange(80, dtype=np.int32)
    write_ply(tmp_path / "f.ply", {"id": ids, "x": p[:, 0], "y": p[:, 1], "z": p[:, 2], "radius": radius}, fmt)
    q, attrs = im.read_particles(tmp_path / "f.ply", attributes=["radius", "id"])
    assert q.dtype == dtype and q.shape == (80, 3)
    np.testing.assert_array_equal(q, p)
    np.testing.assert_array_equal(attrs["radius"], radius)
    np.testing.assert_array_equal(attrs["id"], ids)


def test_binary_ply_of_xyz_only_is_a_view(tmp_path):
    p = frame(100, np.float32)
    write_ply(tmp_path / "f.ply", {"x": p[:, 0], "y": p[:, 1], "z": p[:, 2]})
    q = im.read_particles(tmp_path / "f.ply")
    np.testing.assert_array_equal(q, p)
    assert q.base is not None  # a view of the file's records, not a stacked copy


def _without(monkeypatch, *modules):
    """Makes importing ``modules`` fail, as when they are not installed."""
    real_import = builtins.__import__

    def blocked(name, *args, **kwargs):
        if name in modules:
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", blocked)
    real_find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name in modules else real_find_spec(name, *a))


@pytest.mark.parametrize("reader", ["meshio", "pyvista"])
@pytest.mark.parametrize("suffix", [".vtk", ".vtu", ".vtp"])
def test_vtk_formats_read_back_exactly(tmp_path, monkeypatch, suffix, reader):
    """Files pyvista writes read back bit for bit through meshio (used when installed) and
    through pyvista (without meshio)."""
    pv = pytest.importorskip("pyvista")
    pytest.importorskip("meshio")
    p = frame(70)
    rho = np.linspace(1.0, 2.0, 70)
    cloud = pv.PolyData(p)
    cloud.point_data["density"] = rho
    mesh = cloud.cast_to_unstructured_grid() if suffix == ".vtu" else cloud
    mesh.save(tmp_path / f"f{suffix}")
    if reader == "pyvista":
        _without(monkeypatch, "meshio")
    q, attrs = im.read_particles(tmp_path / f"f{suffix}", attributes=["density"])
    np.testing.assert_array_equal(q, p)
    np.testing.assert_array_equal(attrs["density"], rho)


@pytest.mark.parametrize("suffix", [".vtu", ".vtk"])
def test_files_meshio_writes_read_back_exactly(tmp_path, suffix):
    meshio = pytest.importorskip("meshio")
    p = frame(50)
    ids = np.arange(50, dtype=np.int64)
    meshio.write_points_cells(tmp_path / f"f{suffix}", p, [("vertex", np.arange(50).reshape(-1, 1))],
                              point_data={"id": ids})
    q, attrs = im.read_particles(tmp_path / f"f{suffix}", attributes=["id"])
    np.testing.assert_array_equal(q, p)
    np.testing.assert_array_equal(attrs["id"], ids)


def test_a_file_no_installed_reader_reads_is_refused_naming_the_path(tmp_path, monkeypatch):
    pv = pytest.importorskip("pyvista")
    pytest.importorskip("meshio")
    pv.PolyData(frame(20)).save(tmp_path / "f.vtp")
    _without(monkeypatch, "pyvista")  # meshio has no .vtp reader
    with pytest.raises(ValueError, match=r"^path: cannot read .*f\.vtp.*meshio"):
        im.read_particles(tmp_path / "f.vtp")


def test_meshio_format_without_meshio_or_pyvista_names_the_install(tmp_path, monkeypatch):
    path = tmp_path / "f.vtu"
    path.write_text("<VTKFile/>")
    _without(monkeypatch, "meshio", "pyvista")
    with pytest.raises(ImportError, match="pip install meshio"):
        im.read_particles(path)


def test_bad_files_are_refused_by_name(tmp_path):
    (tmp_path / "f.bgeo").write_bytes(b"\0")
    with pytest.raises(ValueError, match=r"^path: unknown particle file suffix '\.bgeo'"):
        im.read_particles(tmp_path / "f.bgeo")
    with pytest.raises(FileNotFoundError, match="path"):
        im.read_particles(tmp_path / "missing.npy")
    np.save(tmp_path / "flat.npy", np.zeros(9))
    with pytest.raises(ValueError, match=r"^path: .*shape \(9,\)"):
        im.read_particles(tmp_path / "flat.npy")
    np.save(tmp_path / "complex.npy", np.zeros((3, 3), dtype=complex))
    with pytest.raises(ValueError, match="^path: .*complex128"):
        im.read_particles(tmp_path / "complex.npy")
    np.savez(tmp_path / "other.npz", a=np.zeros((3, 3)), b=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="^path: .*pass key="):
        im.read_particles(tmp_path / "other.npz")
    with pytest.raises(ValueError, match="^key: .*no array 'c'"):
        im.read_particles(tmp_path / "other.npz", key="c")
    with pytest.raises(ValueError, match="^key: only .npz"):
        im.read_particles(tmp_path / "flat.npy", key="a")
    with pytest.raises(ValueError, match="^attributes: .*no per-particle 'radius'"):
        im.read_particles(tmp_path / "other.npz", key="a", attributes=["radius"])
    write_ply(tmp_path / "noz.ply", {"x": np.zeros(3), "y": np.zeros(3)})
    with pytest.raises(ValueError, match="^path: .*no vertex properties x, y, z"):
        im.read_particles(tmp_path / "noz.ply")
    (tmp_path / "short.ply").write_bytes(
        b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\nproperty float y\n"
        b"property float z\nend_header\n" + np.zeros(3, "<f4").tobytes()
    )
    with pytest.raises(ValueError, match="^path: .*ends after 1 of 10"):
        im.read_particles(tmp_path / "short.ply")
    (tmp_path / "text.ply").write_text("not a ply\n")
    with pytest.raises(ValueError, match="^path: .*not a PLY"):
        im.read_particles(tmp_path / "text.ply")


def lattice_ball(radius_cells=6, spacing=0.01, seed=1):
    k = np.arange(-radius_cells, radius_cells + 1)
    g = np.stack(np.meshgrid(k, k, k, indexing="ij"), axis=-1).reshape(-1, 3)
    g = g[np.linalg.norm(g, axis=1) <= radius_cells] * spacing
    return g + np.random.default_rng(seed).uniform(-0.1 * spacing, 0.1 * spacing, g.shape)


@pytest.mark.parametrize("suffix", [".npy", ".ply"])
def test_particles_command_meshes_a_frame(tmp_path, capsys, suffix):
    """The command's mesh is polygonize(from_particles(...), method="sparse") over cells of
    cube_size · r, a closed surface of genus 0 around the ball of particles."""
    p = lattice_ball().astype(np.float32)
    path = tmp_path / f"frame{suffix}"
    if suffix == ".npy":
        np.save(path, p)
    else:
        write_ply(path, {"x": p[:, 0], "y": p[:, 1], "z": p[:, 2]})
    out = tmp_path / "out.ply"
    code = main(["particles", str(path), "-o", str(out), "--radius", "0.005", "--no-normals"])
    assert code == 0, capsys.readouterr().err
    assert "triangles" in capsys.readouterr().out
    m = trimesh.load(out, process=False)
    assert m.is_watertight and m.is_winding_consistent and m.euler_number == 2
    field = im.BlobField.from_particles(p, 0.005)
    lo, hi = field.bounds
    want = im.polygonize(field, resolution=int(round((hi - lo).max() / 0.0025)), method="sparse", normals=False)
    assert (len(m.faces), len(m.vertices)) == (len(want.faces), len(want.vertices))
    got = np.asarray(m.vertices)
    np.testing.assert_allclose(got[np.lexsort(got.T)], want.vertices[np.lexsort(want.vertices.T)], atol=1e-6)


def test_particles_command_errors(tmp_path, capsys):
    np.save(tmp_path / "f.npy", lattice_ball(3))
    assert main(["particles", str(tmp_path / "f.npy"), "-o", str(tmp_path / "o.ply"), "--radius", "0"]) == 2
    assert "--radius" in capsys.readouterr().err
    (tmp_path / "f.txt").write_text("0 0 0\n")
    assert main(["particles", str(tmp_path / "f.txt"), "-o", str(tmp_path / "o.ply"), "--radius", "0.01"]) == 2
    assert "unknown particle file suffix" in capsys.readouterr().err
