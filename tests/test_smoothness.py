"""The smoothness metrics of the real-frame benchmark (benchmarks/smoothness.py): flat patches
chosen from particles, a mesh's deviation from planes there, neighbouring normals' angles and the
enclosed volume, on cases whose answers are known."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks import smoothness  # noqa: E402

R = 0.01  # particle radius: particles 2R apart


def slab(nx=60, ny=50, layers=6, seed=3):
    """A jittered lattice slab of particles, spacing 2R, the lowest layer at z = R."""
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), np.arange(layers), indexing="ij"), axis=-1).reshape(-1, 3)
    p = (g + 0.5) * 2 * R
    return p + rng.uniform(-0.1 * R, 0.1 * R, p.shape)


def grid_mesh(x0, x1, y0, y1, height, step):
    """A triangulated height field z = height(x, y) over a rectangle (faces up)."""
    xs, ys = np.arange(x0, x1 + 1e-12, step), np.arange(y0, y1 + 1e-12, step)
    x, y = np.meshgrid(xs, ys, indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), height(x.ravel(), y.ravel())], axis=1)
    ny = len(ys)
    i, j = np.meshgrid(np.arange(len(xs) - 1), np.arange(ny - 1), indexing="ij")
    a = (i * ny + j).ravel()
    b, c, d = a + ny, a + ny + 1, a + 1
    return v, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def test_flat_patches_of_a_slab_are_level_with_its_top_layer():
    p = slab()
    patches = smoothness.flat_patches(p, R)
    # Centres 20 R inside the bounding box on a grid of 10 R: x over [0.2, 1.0], y over [0.2, 0.8].
    lo, hi = p[:, :2].min(axis=0) + 20 * R, p[:, :2].max(axis=0) - 20 * R
    expected = int(np.floor((hi[0] - lo[0]) / (10 * R) + 1e-9) + 1) * int(np.floor((hi[1] - lo[1]) / (10 * R) + 1e-9) + 1)
    assert len(patches) == expected
    top = 11 * R
    assert np.abs(np.hypot(patches[:, 2], patches[:, 3])).max() < 0.05
    plane_at_centre = patches[:, 2] * patches[:, 0] + patches[:, 3] * patches[:, 1] + patches[:, 4]
    assert np.abs(plane_at_centre - top).max() < 0.3 * R


def test_droplets_and_slopes_are_not_flat():
    p = slab()
    # A ball of particles hovering over the middle of the slab: the columns under it are not filled.
    rng = np.random.default_rng(5)
    centre = np.array([0.6, 0.5, 0.3])
    g = np.stack(np.meshgrid(*[np.arange(-4, 5)] * 3, indexing="ij"), axis=-1).reshape(-1, 3) * 2 * R
    ball = centre + g[np.linalg.norm(g, axis=1) <= 8 * R] + rng.uniform(-0.1 * R, 0.1 * R, (1, 3))
    patches = smoothness.flat_patches(np.vstack([p, ball]), R)
    near = np.hypot(patches[:, 0] - centre[0], patches[:, 1] - centre[1]) < 8 * R + 5 * R
    assert len(patches) > 0 and not near.any()
    # The slab tilted by 20° has no flat patch at the default 10°.
    t = np.radians(20)
    tilted = p.copy()
    tilted[:, 2] += np.tan(t) * p[:, 0]
    assert len(smoothness.flat_patches(tilted, R, fill=0.0)) == 0
    assert len(smoothness.flat_patches(tilted, R, fill=0.0, max_tilt=25)) > 0


def test_a_plane_is_perfectly_smooth_and_a_ripple_is_measured():
    p = slab()
    patches = smoothness.flat_patches(p, R)
    top = 11 * R
    box = (-0.1, 1.3, -0.1, 1.1)
    v, f = grid_mesh(*box, lambda x, y: top + R + 0 * x, R / 2)
    flat = smoothness.smoothness(v, f, patches, R)
    assert flat["patches"] == len(patches)
    assert flat["plane_rms_r"] < 1e-9 and flat["normal_angle_deg"] < 1e-6
    amplitude, wavelength = 0.2 * R, 2 * R
    v, f = grid_mesh(*box, lambda x, y: top + R + amplitude * np.sin(2 * np.pi * x / wavelength), R / 8)
    ripple = smoothness.smoothness(v, f, patches, R)
    # The root mean square of A sin over whole periods is A / √2 (a plane fitted to a 10 R patch
    # holds 5 periods: it stays level).
    assert ripple["plane_rms_r"] == pytest.approx(0.2 / np.sqrt(2), rel=0.03)
    assert ripple["normal_angle_deg"] > 1.0
    # A tilted plane is as smooth as a level one: each patch has its own plane.
    v, f = grid_mesh(*box, lambda x, y: top + R + 0.05 * x, R / 2)
    assert smoothness.smoothness(v, f, patches, R)["plane_rms_r"] < 1e-9


def test_faces_away_from_the_top_are_not_measured():
    patches = smoothness.flat_patches(slab(), R)
    v, f = grid_mesh(-0.1, 1.3, -0.1, 1.1, lambda x, y: 0 * x, R / 2)  # the floor: 11 R below the top
    out = smoothness.smoothness(v, f, patches, R)
    assert out["patches"] == 0 and out["faces"] == 0
    assert out["plane_rms_r"] is None and out["normal_angle_deg"] is None


def test_enclosed_volume_of_a_box_and_neighbour_angles_of_a_cube():
    import trimesh

    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    assert smoothness.enclosed_volume(box.vertices, box.faces) == pytest.approx(6.0, rel=1e-12)
    normals, areas = smoothness.face_normals(box.vertices, box.faces)
    assert areas.sum() == pytest.approx(2 * (2 + 3 + 6), rel=1e-12)
    angles = smoothness.neighbour_angles(box.faces, normals, np.ones(len(box.faces), dtype=bool))
    # 18 edges: 12 cube edges at 90°, 6 face diagonals at 0°.
    assert len(angles) == 18
    assert sorted(np.round(angles, 9)) == [0.0] * 6 + [90.0] * 12


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="particles"):
        smoothness.flat_patches(np.zeros((10, 2)), R)
    with pytest.raises(ValueError, match="radius"):
        smoothness.flat_patches(slab(), 0.0)


def test_frame_case_runs_ours_and_splashsurf_on_a_cached_frame(tmp_path, monkeypatch):
    """A frame case of benchmarks/frame_cases.py end to end on a jittered slab stored as a cached
    frame: our colour field and splashsurf make the same surface (volume and flatness), the
    anisotropic case runs and is flatter."""
    import json

    from benchmarks import frame_cases, sph_frames

    scene = "dam-break-1e5"
    d = tmp_path / scene
    d.mkdir()
    p = slab(40, 30, 6)
    np.save(d / sph_frames.frame_name(0.5), p.astype(np.float32))
    box = [[0.0, 0.0, 0.0], [0.8, 0.6, 1.0]]
    (d / "scene.json").write_text(json.dumps({"particle_radius": R, "box": box, "frames": [
        {"file": sph_frames.frame_name(0.5), "time": 0.5, "particles": len(p)}]}))
    monkeypatch.setenv(sph_frames.ENV_CACHE, str(tmp_path))
    ours = frame_cases.one(scene, "colour-f32", 500, lambda: 0.0)
    peer = frame_cases.one(scene, "splashsurf-f32", 500, lambda: 0.0)
    assert ours["particles"] == peer["particles"] == len(p)
    assert ours["flat_patches"] == peer["flat_patches"] == len(smoothness.flat_patches(
        p.astype(np.float32).astype(np.float64), R, walls=([0, 0], [0.8, 0.6]), floor=0.0)) > 0
    assert ours["patches"] == ours["flat_patches"]
    assert ours["volume"] == pytest.approx(peer["volume"], rel=2e-3)
    assert ours["plane_rms_r"] == pytest.approx(peer["plane_rms_r"], abs=0.01)
    # The slab's top face (a jittered lattice, isotropic kernels) is within a few hundredths of r of a plane.
    assert ours["plane_rms_r"] < 0.1
    # The anisotropic case runs on the same patches and is flatter there (its volume loss on a
    # slab this thin is documented in docs/particles.md, not asserted).
    aniso = frame_cases.one(scene, "colour-aniso-f32", 500, lambda: 0.0)
    assert "skipped" not in aniso
    assert aniso["flat_patches"] == ours["flat_patches"]
    assert 0 < aniso["plane_rms_r"] < ours["plane_rms_r"]
    assert 0 < aniso["volume"] < ours["volume"]
    assert frame_cases.one(scene, "colour", 600, lambda: 0.0)["skipped"].startswith("no frame at 0.6 s")
