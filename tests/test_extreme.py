"""Extreme magnitudes and panics: every public entry point takes coordinates over the whole
finite range (tests/_magnitudes.py, each check in its own process so that a crash or a hang
fails one test and nothing else), and a panic in the core's work comes back as a RuntimeError
at once, leaving the process usable."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import warnings

import numpy as np
import pytest

import implicitmesh as im
from implicitmesh import _core

HERE = os.path.dirname(os.path.abspath(__file__))
#: Catches hangs only: each check takes a few seconds.
TIMEOUT = 300


def isolated(code: str) -> subprocess.CompletedProcess:
    """Runs `code` in a new Python process (in tests/, under an 8 GB address-space limit where
    the platform has one) and returns it finished; a hang fails the test at TIMEOUT."""
    def limit():
        try:
            import resource

            resource.setrlimit(resource.RLIMIT_AS, (8_000_000_000, 8_000_000_000))
        except (ImportError, ValueError, OSError):
            pass

    return subprocess.run(
        [sys.executable, "-c", code], cwd=HERE, capture_output=True, text=True, timeout=TIMEOUT,
        preexec_fn=limit if os.name == "posix" else None,
    )


@pytest.mark.parametrize("check", ["check_fits", "check_meshes", "check_blobs", "check_polygonize", "check_states"])
def test_magnitudes_give_a_result_or_a_clear_error(check):
    r = isolated(f"import _magnitudes; _magnitudes.{check}(); print('ok')")
    assert r.returncode == 0 and r.stdout.strip().endswith("ok"), r.stderr[-4000:]
    assert "panicked" not in r.stderr, r.stderr[-4000:]


@pytest.mark.parametrize("on_caller", [False, True])
def test_a_panic_in_a_worker_is_a_runtime_error_and_the_next_call_works(on_caller):
    r = isolated(
        "import numpy as np, implicitmesh as im\n"
        "from implicitmesh import _core\n"
        "for _ in range(3):\n"
        "    try:\n"
        f"        _core._panic_in_worker(on_caller={on_caller})\n"
        "    except RuntimeError as e:\n"
        "        assert '_panic_in_worker' in str(e) and 'a panic forced for testing' in str(e), e\n"
        "    else:\n"
        "        raise AssertionError('no error')\n"
        "    m = im.polygonize(im.BlobField(np.zeros((1, 3)), 0.8), bounds=[[-1] * 3, [1] * 3], resolution=16, method='sparse')\n"
        "    assert len(m.faces) > 0\n"
        "print('ok')\n"
    )
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr[-4000:]


def test_the_panic_hook_is_there_in_process():
    # In this process too: the error is raised at once, and the pool still works after.
    with pytest.raises(RuntimeError, match="_panic_in_worker: internal error, a panic in the core: a panic forced"):
        _core._panic_in_worker()
    assert len(im.BlobField(np.zeros((1, 3)), 0.8).evaluate(np.zeros((100_000, 3)))) == 100_000


def _cloud(far: float | None = None, n: int = 1000) -> np.ndarray:
    p = np.random.default_rng(0).uniform(-1, 1, (n, 3))
    return p if far is None else np.vstack([p, [[far, 0, 0]]])


@pytest.mark.parametrize("far", [1e6, 1e30, 1e200, 1.7e308])
def test_far_particles_and_blobs_are_refused_naming_the_entry(far):
    for call, name in [(lambda: im.BlobField.from_particles(_cloud(far), 0.01), "particles"), (lambda: im.BlobField(_cloud(far), 0.1), "centers")]:
        with pytest.raises(ValueError, match=rf"^{name}: entry 1000 lies .* times the extent of their bulk"):
            call()


def test_particles_spanning_more_than_a_float_holds_are_refused():
    p = np.array([[-1.7e308, 0, 0], [1.7e308, 0, 0]] * 4) + np.arange(8)[:, None] * [0, 1, 0]
    with pytest.raises(ValueError, match="particles: the entries span .* squared distances between them overflow"):
        im.BlobField.from_particles(p, 0.1)


def test_blobs_at_a_large_offset_are_kept():
    # Magnitude alone is no fault: the same cloud far from the origin is accepted as it is.
    b = im.BlobField(_cloud() * 1e-3 + 1e12, 1e-4)
    assert len(b) == 1000 and np.isfinite(b.bounds).all()


@pytest.mark.parametrize("far", [1e6, 1e30, 1e200])
def test_a_fit_with_a_far_point_says_which_and_how_far(far):
    p, n = im.shapes.fibonacci_sphere(500)
    p, n = np.vstack([p, [[far, 0, 0]]]), np.vstack([n, [[1, 0, 0]]])
    with pytest.raises(ValueError, match=r"^points: entry 500 lies .* times the extent of their bulk.*more than 1000 times is refused"):
        im.VariationalSurface.fit(p, n, exact=True)


def test_a_point_outside_the_bulk_is_fitted_but_left_out_of_the_default_bounds():
    p, n = im.shapes.fibonacci_sphere(500)
    near = im.VariationalSurface.fit(p, n, exact=True)
    with pytest.warns(UserWarning, match=r"points: entry 500 lies 1.000e2 .* default bounds"):
        s = im.VariationalSurface.fit(np.vstack([p, [[100, 0, 0]]]), np.vstack([n, [[1, 0, 0]]]), exact=True)
    assert np.array_equal(s.bounds, near.bounds)
    assert abs(s.evaluate([[100.0, 0, 0]])[0]) < 1e-6
    # And the same bounds after a round trip.
    assert np.array_equal(pickle.loads(pickle.dumps(s)).bounds, near.bounds)
    # Without far points, no warning.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        im.VariationalSurface.fit(p, n, exact=True)


def test_a_saved_partition_fit_with_a_far_constraint_is_refused(tmp_path):
    p, n = im.shapes.fibonacci_sphere(300)
    s = im.VariationalSurface.fit(p, n, method="partition", partition_options={"max_per_leaf": 16, "min_points": 8, "max_patch": 40}, exact=True)
    for far in (1e200, 1e308):
        state = s.to_state()
        state["constraint_points"] = state["constraint_points"].copy()
        state["constraint_points"][5] = [far, 0, 0]
        with pytest.raises(ValueError, match="constraint_points: entry 5 lies"):
            im.VariationalSurface.from_state(state)
        im.save(tmp_path / "s.npz", s)
        with np.load(tmp_path / "s.npz") as z:
            saved = dict(z)
        saved["constraint_points"] = state["constraint_points"]
        np.savez(tmp_path / "s.npz", **saved)
        with pytest.raises(ValueError, match="constraint_points: entry 5 lies"):
            im.load(tmp_path / "s.npz")
