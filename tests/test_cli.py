"""The command line: ``python -m implicitmesh demo`` and ``reconstruct``."""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path
import sys

import numpy as np
import pytest
import trimesh

from conftest import genus_of, vertex_normals_area_weighted


def run_cli(*args, cwd):
    env = dict(os.environ, MPLBACKEND="Agg")
    return subprocess.run(
        [sys.executable, "-m", "implicitmesh", *map(str, args)],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def table_value(stdout: str, key: str) -> str:
    m = re.search(rf"^\s*{key}\s+(.+?)\s*$", stdout, flags=re.MULTILINE)
    assert m, f"no '{key}' row in the printed table:\n{stdout}"
    return m.group(1)


def load_closed(path):
    m = trimesh.load(path, process=False)
    assert isinstance(m, trimesh.Trimesh)
    assert len(m.faces) > 0
    assert m.is_watertight
    assert m.is_winding_consistent
    assert m.volume > 0
    return m


def test_demo(tmp_path):
    out = tmp_path / "demo"
    r = run_cli("demo", "-o", out, "--resolution", 48, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    ply, png = out / "knot.ply", out / "knot.png"
    assert ply.is_file() and ply.stat().st_size > 0
    assert png.is_file() and png.stat().st_size > 0
    # The table.
    assert table_value(r.stdout, "watertight") == "yes"
    assert table_value(r.stdout, "genus") == "1"
    assert "48x48x48" in table_value(r.stdout, "method")
    # The PLY is the mesh the table describes: closed, genus 1 (the knot), same triangle count.
    m = load_closed(ply)
    assert genus_of(m.euler_number) == 1
    assert int(table_value(r.stdout, "triangles").replace(",", "")) == len(m.faces)
    # The PNG is a real picture, not a blank canvas.
    import matplotlib.image

    img = matplotlib.image.imread(png)
    assert img.ndim == 3 and img.shape[2] in (3, 4)
    assert img.shape[0] > 100 and img.shape[1] > 100
    assert np.asarray(img[..., :3], dtype=float).std() > 0.01
    # Nothing was written outside the output folder.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo"]


def test_reconstruct_mesh_ply(mesh_dir, tmp_path):
    src = mesh_dir / "torus2_800.ply"
    out = tmp_path / "torus2_out.ply"
    r = run_cli("reconstruct", src, "-o", out, "--resolution", 48, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert table_value(r.stdout, "watertight") == "yes"
    m = load_closed(out)
    assert m.body_count == 1
    assert genus_of(m.euler_number) == 2
    assert table_value(r.stdout, "genus") == "2"
    # The reconstruction lies where the input is.
    src_mesh = trimesh.load(src, process=False)
    np.testing.assert_allclose(m.bounds, src_mesh.bounds, atol=0.05)


def test_reconstruct_projects_vertices_unless_told_not_to(mesh_dir, tmp_path):
    """reconstruct moves the vertices onto the fitted surface by default; --no-project keeps
    marching cubes' vertices. Same faces either way."""
    from implicitmesh import VariationalSurface

    src = mesh_dir / "torus2_800.ply"
    meshes = []
    for flag in ("--project", "--no-project"):
        out = tmp_path / f"out{flag}.ply"
        r = run_cli("reconstruct", src, "-o", out, "--resolution", 32, flag, cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        meshes.append(load_closed(out))
    projected, plain = meshes
    np.testing.assert_array_equal(projected.faces, plain.faces)
    m = trimesh.load(src, process=False)
    surface = VariationalSurface.from_mesh(np.asarray(m.vertices), np.asarray(m.faces))
    err = [np.abs(surface(np.asarray(x.vertices))).mean() for x in (projected, plain)]
    assert err[0] < err[1] / 10


def test_reconstruct_xyz_points_with_normals(mesh_dir, tmp_path):
    src = trimesh.load(mesh_dir / "star_800.ply", process=False)
    v, f = np.asarray(src.vertices), np.asarray(src.faces)
    xyz = tmp_path / "star.xyz"
    np.savetxt(xyz, np.hstack([v, vertex_normals_area_weighted(v, f)]))
    out = tmp_path / "star_out.ply"
    r = run_cli("reconstruct", xyz, "-o", out, "--resolution", 40, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert table_value(r.stdout, "watertight") == "yes"
    m = load_closed(out)
    assert genus_of(m.euler_number) == 0
    np.testing.assert_allclose(m.bounds, src.bounds, atol=0.05)


def test_reconstruct_a_scan_prints_its_report_and_trims(tmp_path):
    from implicitmesh.scanner import scan

    src = trimesh.load(Path(__file__).parent / "data" / "meshes" / "spot_hires.ply", process=False)
    s = scan(np.asarray(src.vertices), np.asarray(src.faces), 10_000, noise=5e-4, outliers=2e-3, seed=2)
    npz = tmp_path / "scan.npz"
    np.savez(npz, points=s.points, normals=s.normals)
    closed, opened = tmp_path / "closed.ply", tmp_path / "open.ply"
    r = run_cli("reconstruct", npz, "-o", closed, "--resolution", 64, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "left out" in table_value(r.stdout, "outliers")
    assert table_value(r.stdout, "watertight") == "yes"
    spacing = float(table_value(r.stdout, "noise").split("spacing ")[1].rstrip(")"))
    r = run_cli("reconstruct", npz, "-o", opened, "--resolution", 64, "--trim", 2 * spacing, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert table_value(r.stdout, "watertight") == "no"
    assert int(table_value(r.stdout, "trimmed").split()[0].replace(",", "")) > 0
    r = run_cli("reconstruct", npz, "-o", tmp_path / "exact.ply", "--resolution", 32, "--exact", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "outliers" not in r.stdout


def test_missing_input_file(tmp_path):
    missing = tmp_path / "no_such_mesh.ply"
    out = tmp_path / "out.ply"
    r = run_cli("reconstruct", missing, "-o", out, "--resolution", 16, cwd=tmp_path)
    assert r.returncode == 2
    assert "error" in r.stderr.lower()
    assert "no_such_mesh" in r.stderr
    assert "Traceback" not in r.stderr
    assert not out.exists()


def test_xyz_with_too_few_columns(tmp_path):
    xyz = tmp_path / "bad.xyz"
    np.savetxt(xyz, np.random.default_rng(0).normal(size=(20, 5)))
    out = tmp_path / "out.ply"
    r = run_cli("reconstruct", xyz, "-o", out, "--resolution", 16, cwd=tmp_path)
    assert r.returncode == 2
    assert "error" in r.stderr.lower() and "6 columns" in r.stderr
    assert "Traceback" not in r.stderr
    assert not out.exists()


def write_point_ply(path, points, normals=None, binary=False):
    """A PLY point set (vertices only) with float x y z and, if given, nx ny nz."""
    names = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals is not None else [])
    cols = np.hstack([points] + ([normals] if normals is not None else [])).astype(np.float32)
    header = (
        f"ply\nformat {'binary_little_endian' if binary else 'ascii'} 1.0\nelement vertex {len(cols)}\n"
        + "".join(f"property float {k}\n" for k in names)
        + "end_header\n"
    )
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        if binary:
            f.write(cols.astype("<f4").tobytes())
        else:
            f.write("".join(" ".join(repr(float(x)) for x in row) + "\n" for row in cols).encode("ascii"))


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_reconstruct_ply_point_set_with_normals(mesh_dir, tmp_path, capsys, binary):
    """The documented input 'a PLY point set with nx ny nz', in both PLY encodings (run in-process
    to keep the suite fast)."""
    from implicitmesh.cli import main

    src = trimesh.load(mesh_dir / "star_800.ply", process=False)
    v, f = np.asarray(src.vertices), np.asarray(src.faces)
    ply = tmp_path / "points.ply"
    write_point_ply(ply, v, vertex_normals_area_weighted(v, f), binary=binary)
    out = tmp_path / "out.ply"
    code = main(["reconstruct", str(ply), "-o", str(out), "--resolution", "32"])
    assert code == 0
    assert table_value(capsys.readouterr().out, "watertight") == "yes"
    m = load_closed(out)
    assert genus_of(m.euler_number) == 0


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_ply_point_set_without_normals_gets_them_estimated(tmp_path, capsys, binary):
    from implicitmesh.cli import main

    ply = tmp_path / "points.ply"
    s = np.random.default_rng(0).normal(size=(2000, 3))
    write_point_ply(ply, s / np.linalg.norm(s, axis=1)[:, None], binary=binary)
    code = main(["reconstruct", str(ply), "-o", str(tmp_path / "out.ply"), "--resolution", "24"])
    assert code == 0
    out = capsys.readouterr().out
    assert table_value(out, "normals").startswith("estimated")
    assert table_value(out, "watertight") == "yes"


@pytest.mark.parametrize(
    "args, option",
    [
        (["reconstruct", "{mesh}", "-o", "{tmp}/out.ply", "--resolution", "0"], "--resolution"),
        (["reconstruct", "{mesh}", "-o", "{tmp}/out.ply", "--resolution", "-3"], "--resolution"),
        (["reconstruct", "{mesh}", "-o", "{tmp}/out.ply", "--resolution", "2000000"], "--resolution"),
        (["reconstruct", "{mesh}", "-o", "{tmp}/out.foo"], "--output"),
        (["reconstruct", "{mesh}", "-o", "{tmp}/out"], "--output"),
        (["reconstruct", "{mesh}", "-o", "{tmp}/missing/out.ply"], "--output"),
        (["reconstruct", "{mesh}", "-o", "{tmp}/out.ply", "--method", "sparse"], "--method"),
        (["reconstruct", "{mesh}", "-o", "{tmp}/out.ply", "--kernel", "gaussian"], "--kernel"),
        (["reconstruct", "{mesh}", "-o", "{tmp}/out.ply", "--d", "-0.01"], "--d"),
        (["reconstruct", "{mesh}", "-o", "{tmp}/out.ply", "--w", "0"], "--w"),
        (["reconstruct", "{mesh}", "-o", "{tmp}/out.ply", "--trim", "-1"], "--trim"),
        (["reconstruct", "{mesh}", "-o", "{tmp}/out.ply", "--trim", "nan"], "--trim"),
        (["reconstruct", "{tmp}/absent.ply", "-o", "{tmp}/out.ply"], "absent.ply"),
        (["demo", "-o", "{tmp}/demo", "--resolution", "0"], "--resolution"),
        (["demo", "-o", "{tmp}/demo", "--method", "sparse"], "--method"),
        (["demo", "-o", "{tmp}/demo", "--model", "bunny"], "--model"),
        (["particles", "{tmp}/absent.npy", "-o", "{tmp}/out.ply", "--radius", "0.1"], "absent.npy"),
        (["particles", "{points}", "-o", "{tmp}/out.ply", "--radius", "0"], "--radius"),
        (["particles", "{points}", "-o", "{tmp}/out.ply", "--radius", "0.1", "--cube-size", "-1"], "--cube-size"),
        (["particles", "{points}", "-o", "{tmp}/out.ply", "--radius", "0.1", "--smoothing-length", "0"], "--smoothing-length"),
        (["particles", "{points}", "-o", "{tmp}/out.ply", "--radius", "0.1", "--threshold", "nan"], "--threshold"),
        (["particles", "{points}", "-o", "{tmp}/out.xyz.gz", "--radius", "0.1"], "--output"),
        (["particles", "{points}", "-o", "{tmp}/out.ply", "--radius", "0.1", "--min-particles", "-1"], "--min-particles"),
        (["particles", "{points}", "-o", "{tmp}/out.ply", "--radius", "0.1", "--precision", "half"], "--precision"),
    ],
    ids=lambda a: " ".join(a) if isinstance(a, list) else a,
)
def test_every_argument_is_refused_before_any_work(mesh_dir, tmp_path, capsys, monkeypatch, args, option):
    """A bad argument is refused before the input is read or anything fitted: exit 2 and one
    line on standard error naming the option (or the missing file)."""
    import implicitmesh.cli as cli

    def no_work(*a, **k):
        raise AssertionError("work started before the arguments were checked")

    monkeypatch.setattr(cli, "_read_input", no_work)
    monkeypatch.setattr(cli, "_fit_and_polygonize", no_work)
    monkeypatch.setattr("implicitmesh.frames.read_particles", no_work)
    points = tmp_path / "points.npy"
    np.save(points, np.zeros((4, 3)))
    argv = [a.format(mesh=mesh_dir / "torus2_800.ply", tmp=tmp_path, points=points) for a in args]
    try:
        code = cli.main(argv)
    except SystemExit as e:  # argparse's own refusals (a choice, a number)
        code = e.code
    assert code == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("implicitmesh") and "error" in lines[0], err
    assert option in lines[0]
    assert not (tmp_path / "out.ply").exists() and not (tmp_path / "demo").exists()


def test_every_option_has_help():
    """Every option and argument of every command says what it is in --help."""
    import argparse

    import implicitmesh.cli as cli

    parsers = []
    original = argparse.ArgumentParser.parse_args

    def keep(self, *a, **k):
        parsers.append(self)
        raise SystemExit(0)

    argparse.ArgumentParser.parse_args = keep
    try:
        with pytest.raises(SystemExit):
            cli.main(["demo"])
    finally:
        argparse.ArgumentParser.parse_args = original
    (parser,) = parsers
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert sorted(sub.choices) == ["demo", "particles", "reconstruct"]
    for name, command in sub.choices.items():
        for action in command._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            assert action.help, f"{name} {action.option_strings or action.dest} has no help"
    # Only the methods that fit the input: a fitted surface is never offered "sparse".
    for name in ("demo", "reconstruct"):
        method = next(a for a in sub.choices[name]._actions if "--method" in a.option_strings)
        assert "sparse" not in method.choices and "octree" in method.choices


def test_particles_anisotropic_single_and_fragments(tmp_path, capsys):
    """``particles --anisotropic --precision single --min-particles K``: the field of
    ``from_particles(..., anisotropic=True, precision="single")``, the droplet of 8 particles
    dropped and counted, and the lattice's actual cell side printed."""
    from implicitmesh.cli import main

    import implicitmesh as im

    rng = np.random.default_rng(3)
    i = np.stack(np.meshgrid(*[np.arange(8)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    drop = np.stack(np.meshgrid(*[np.arange(2)] * 3, indexing="ij"), axis=-1).reshape(-1, 3) + 20
    p = np.vstack([i, drop]) * 0.1 + rng.uniform(-0.01, 0.01, (len(i) + 8, 3))
    np.save(tmp_path / "f.npy", p)
    out = tmp_path / "s.ply"
    code = main(["particles", str(tmp_path / "f.npy"), "-o", str(out), "--radius", "0.05", "--anisotropic", "--precision", "single", "--min-particles", "10"])
    assert code == 0
    text = capsys.readouterr().out
    assert "1 bodies of fewer than 10 particles (8 particles)" in text
    field = im.BlobField.from_particles(p, 0.05, anisotropic=True, precision="single")
    lo, hi = field.bounds
    cells = int(round(float((hi - lo).max()) / 0.025))
    mesh = im.polygonize(field, resolution=cells, method="sparse", min_particles=10)
    side = float((np.asarray(mesh.stats["bounds"])[1, 0] - np.asarray(mesh.stats["bounds"])[0, 0]) / cells)
    assert f"of side {side:.6g}" in text and side != 0.025
    written = im.Mesh(*_read_ply(out))
    assert len(written.faces) == len(mesh.faces) and written.euler_number == 2


def _read_ply(path):
    import trimesh

    m = trimesh.load(path, process=False)
    return np.asarray(m.vertices, dtype=float), np.asarray(m.faces), np.zeros((0, 3)), {}
