"""Normals of points without them (:func:`implicitmesh.estimate_normals`): scans of the shared
meshes oriented outward, thin parts and nearby sheets, viewpoints, open data, bad input,
separate pieces, and the scan fit and the command line from positions alone."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

import implicitmesh as im
from implicitmesh.scanner import scan

from test_cli import run_cli, table_value

MESHES = Path(__file__).parent / "data" / "meshes"


def _truth(name: str):
    m = trimesh.load(MESHES / f"{name}_hires.ply", process=False)
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def _face_normals(v, f):
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    return n / np.linalg.norm(n, axis=1)[:, None]


def _inward(normals, truth) -> float:
    """The fraction of normals more than 90° from the true ones."""
    return float(np.mean(np.einsum("ij,ij->i", normals, truth) <= 0))


def _scan(name, noise):
    v, f = _truth(name)
    s = scan(v, f, 20_000, noise=noise, seed=3)
    return s, _face_normals(v, f)[s.triangle]


@pytest.mark.parametrize("name", ["knot", "torus2", "spot", "fandisk", "star"])
@pytest.mark.parametrize("noise", [0.0, 2e-3])
def test_scans_are_oriented_outward(name, noise):
    s, truth = _scan(name, noise)
    n = im.estimate_normals(s.points)
    assert n.shape == s.points.shape and n.dtype == np.float64
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    assert _inward(n, truth) <= 0.005


def test_viewpoints_give_the_same_orientation():
    s, truth = _scan("knot", 5e-4)
    plain = im.estimate_normals(s.points)
    per_point = im.estimate_normals(s.points, viewpoints=s.cameras[s.view])
    one = im.estimate_normals(s.points, viewpoints=s.cameras[0])
    assert np.mean(np.einsum("ij,ij->i", plain, per_point) > 0) >= 0.995
    assert np.mean(np.einsum("ij,ij->i", plain, one) > 0) >= 0.995
    assert _inward(per_point, truth) <= 0.005


def _even_samples(mesh: trimesh.Trimesh, n: int, seed: int):
    p, face = trimesh.sample.sample_surface_even(mesh, n, seed=seed)
    return np.asarray(p), np.asarray(mesh.face_normals[face])


def test_a_thin_plate_is_oriented_on_both_sides():
    # 1 × 1 × 0.03: the plate is about 3 spacings thick.
    plate = trimesh.creation.box((1.0, 1.0, 0.03))
    p, truth = _even_samples(plate, 20_000, 1)
    n = im.estimate_normals(p)
    # Away from the rim (2 spacings), where a neighbourhood holds points of both sides and of
    # the rim's narrow faces, every normal points out of its side.
    inner = np.all(np.abs(p[:, :2]) < 0.5 - 0.02, axis=1)
    for side in (1, -1):
        on = inner & (truth[:, 2] == side)
        assert on.sum() > 8000 and np.all(np.sign(n[on, 2]) == side)


def test_two_nearby_sheets_warn_and_each_faces_out():
    # Two plates 0.04 apart (about 3 spacings): two pieces, each oriented on its own.
    a = trimesh.creation.box((1.0, 1.0, 0.04))
    b = a.copy()
    b.apply_translation((0, 0, 0.08))
    p, truth = _even_samples(trimesh.util.concatenate([a, b]), 30_000, 2)
    with pytest.warns(UserWarning, match="2 pieces"):
        n = im.estimate_normals(p)
    inner = np.all(np.abs(p[:, :2]) < 0.5 - 0.02, axis=1) & (truth[:, 2] != 0)
    assert _inward(n[inner], truth[inner]) == 0


def test_separate_spheres_warn_and_each_faces_out():
    i = np.arange(4000) + 0.5
    z, phi = 1 - 2 * i / 4000, np.pi * (1 + 5**0.5) * i
    s = np.column_stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z])
    p = np.vstack([s, 0.5 * s + (3, 0, 0), 0.3 * s + (0, 4, 1)])
    truth = np.vstack([s, s, s])
    with pytest.warns(UserWarning, match="3 pieces"):
        n = im.estimate_normals(p)
    assert _inward(n, truth) == 0


def test_a_noisy_height_field_faces_up_or_its_viewpoint():
    rng = np.random.default_rng(5)
    xy = rng.uniform(-1, 1, (20_000, 2))
    z = 0.3 * np.sin(2 * xy[:, 0]) * np.cos(3 * xy[:, 1]) + rng.normal(0, 2e-3, len(xy))
    p = np.column_stack([xy, z])
    n = im.estimate_normals(p)
    assert np.all(n[:, 2] > 0)
    n = im.estimate_normals(p, viewpoints=(0.0, 0.0, -5.0))
    assert np.all(n[:, 2] < 0)


def test_bad_input_is_refused_naming_the_argument():
    rng = np.random.default_rng(1)
    p = rng.normal(size=(100, 3))
    with pytest.raises(ValueError, match="^points:.*neighbours"):
        im.estimate_normals(p[:10])
    with pytest.raises(ValueError, match="^points:.*line"):
        im.estimate_normals(np.outer(np.arange(50.0), (1, 2, 3)))
    with pytest.raises(ValueError, match="^points:.*plane"):
        im.estimate_normals(np.column_stack([p[:, :2], p[:, 0] - p[:, 1]]))
    bad = p.copy()
    bad[7, 1] = np.nan
    with pytest.raises(ValueError, match="^points:.*7"):
        im.estimate_normals(bad)
    with pytest.raises(ValueError, match="^neighbours:"):
        im.estimate_normals(p, neighbours=2)
    with pytest.raises(ValueError, match="^viewpoints:"):
        im.estimate_normals(p, viewpoints=np.zeros((5, 3)))
    with pytest.raises(ValueError, match="^viewpoints:"):
        im.estimate_normals(p, viewpoints=(0.0, np.inf, 0.0))


def test_the_scan_fit_from_positions_alone_gives_one_body_of_the_true_genus():
    s, _ = _scan("knot", 5e-4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        surface = im.VariationalSurface.fit(s.points)
    assert surface.report["normals_estimated"] is True
    mesh = im.polygonize(surface, resolution=96, method="octree")
    tm = mesh.to_trimesh()
    assert tm.is_watertight
    assert len(tm.split(only_watertight=False)) == 1
    assert tm.euler_number == 0  # genus 1
    with pytest.raises(ValueError, match="^normals:"):
        im.VariationalSurface.fit(s.points, exact=True)
    with pytest.raises(ValueError, match="^viewpoints:"):
        im.VariationalSurface.fit(s.points, s.normals, viewpoints=(0.0, 0.0, 5.0))


def test_reconstruct_from_an_xyz_file_of_positions(tmp_path):
    v, f = _truth("spot")
    s = scan(v, f, 10_000, noise=5e-4, seed=4)
    xyz = tmp_path / "spot.xyz"
    np.savetxt(xyz, s.points)
    out = tmp_path / "spot.ply"
    r = run_cli("reconstruct", xyz, "-o", out, "--resolution", 64, "--viewpoint", 0, 0, 5, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert table_value(r.stdout, "normals").startswith("estimated")
    assert table_value(r.stdout, "watertight") == "yes"
    r = run_cli("reconstruct", xyz, "-o", out, "--viewpoint", 0, "nan", 5, cwd=tmp_path)
    assert r.returncode != 0 and "--viewpoint" in r.stderr
