"""Long calls stop on Ctrl-C (KeyboardInterrupt) and report progress."""

from __future__ import annotations

import _thread
import signal
import threading
import time

import numpy as np
import pytest

import implicitmesh as im

BOX = [[-1, -1, -1], [1, 1, 1]]


def interrupt_after(seconds: float) -> threading.Timer:
    """Delivers a SIGINT to the main thread after `seconds`, as Ctrl-C does."""
    t = threading.Timer(seconds, _thread.interrupt_main)
    t.start()
    return t


@pytest.fixture(autouse=True)
def python_handles_ctrl_c():
    """Python's own SIGINT handler, which raises KeyboardInterrupt: a process started in the
    background by a non-interactive shell inherits SIGINT ignored, and then a simulated Ctrl-C
    would do nothing."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


@pytest.fixture(scope="module")
def surface():
    return im.VariationalSurface.fit(*im.shapes.fibonacci_sphere(1500), exact=True)


@pytest.mark.parametrize(("method", "resolution"), [("dense", 600), ("octree", 1000)])
def test_ctrl_c_stops_a_long_polygonization(surface, method, resolution):
    # 600³ cells dense or 1000³ by octree against 3,000 centres: several times the 1.5 s after
    # which Ctrl-C comes. The call must end with KeyboardInterrupt, not a mesh, and the next
    # call must work normally.
    counts: list[int] = []
    timer = interrupt_after(1.5)
    try:
        with pytest.raises(KeyboardInterrupt):
            im.polygonize(surface, bounds=BOX, resolution=resolution, method=method, progress=counts.append)
    finally:
        timer.cancel()
    assert counts, "no progress was reported before the interrupt"
    assert counts[-1] < (resolution + 1) ** 3
    mesh = im.polygonize(surface, bounds=BOX, resolution=24, method=method)
    assert mesh.to_trimesh().is_watertight


def test_ctrl_c_stops_a_python_callable_field():
    def slow_sphere(p):
        return np.linalg.norm(p, axis=1) - 0.5

    timer = interrupt_after(0.3)
    try:
        with pytest.raises(KeyboardInterrupt):
            im.polygonize(slow_sphere, bounds=BOX, resolution=1500, batch_size=4096)
    finally:
        timer.cancel()


def test_progress_counts_the_evaluations(surface):
    counts: list[int] = []
    mesh = im.polygonize(surface, bounds=BOX, resolution=48, method="dense", normals=False, progress=counts.append)
    assert counts and counts == sorted(counts)
    assert counts[-1] == mesh.stats["evaluations"] == 49**3
    counts.clear()
    mesh = im.polygonize(surface, bounds=BOX, resolution=48, method="octree", progress=counts.append)
    assert counts[-1] == mesh.stats["evaluations"] + mesh.stats["normal_evaluations"]


def test_progress_true_writes_a_line_or_a_bar(surface, capsys):
    im.polygonize(surface, bounds=BOX, resolution=16, progress=True)
    err = capsys.readouterr().err
    assert "polygonize" in err


def test_progress_must_be_a_bool_or_callable(surface):
    with pytest.raises(ValueError, match="progress"):
        im.polygonize(surface, bounds=BOX, resolution=8, progress="yes")


def test_an_exception_from_the_progress_callback_stops_the_call(surface):
    def boom(done):
        raise RuntimeError("stop here")

    with pytest.raises(RuntimeError, match="stop here"):
        im.polygonize(surface, bounds=BOX, resolution=600, progress=boom)


@pytest.fixture(scope="module")
def many_blobs():
    """2·10⁴ small blobs filling the box: at 800³ cells, tens of seconds of tracking."""
    rng = np.random.default_rng(1)
    return im.BlobField(rng.uniform(-0.9, 0.9, (20000, 3)), 0.03)


@pytest.mark.parametrize("call", ["polygonize", "blocks", "cells"])
def test_ctrl_c_stops_tracking_on_blobs(many_blobs, call):
    # polygonize(method="tracking") and the Tessellator cell by cell and block by block (whose
    # waves of blocks and bounds of blocks are checked batch by batch): the call ends with
    # KeyboardInterrupt soon after the interrupt, and the next call works.
    counts: list[int] = []
    run = {
        "polygonize": lambda **kw: im.polygonize(many_blobs, method="tracking", **kw),
        "blocks": lambda **kw: im.Tessellator().polygonize(many_blobs, **kw),
        "cells": lambda **kw: im.Tessellator().polygonize(many_blobs, blocks=False, **kw),
    }[call]
    timer = interrupt_after(1.5)
    start = time.monotonic()
    try:
        with pytest.raises(KeyboardInterrupt):
            run(bounds=BOX, resolution=800, progress=counts.append)
    finally:
        timer.cancel()
    assert time.monotonic() - start < 6.0
    if call == "blocks":
        assert counts, "no progress was reported before the interrupt"
    mesh = run(bounds=BOX, resolution=16)
    assert len(mesh.faces) > 0


def test_ctrl_c_stops_subdivision():
    v, f = im.shapes.load_model("knot")
    timer = interrupt_after(1.0)
    try:
        with pytest.raises(KeyboardInterrupt):
            # Level 6 has 6.5 million triangles: tens of seconds of Newton steps.
            im.subdivide(v, f, levels=6, field=im.shapes.Torus(major=0.5, minor=0.2))
    finally:
        timer.cancel()


def test_ctrl_c_stops_a_subdivision_reporting_progress(surface):
    control = im.polygonize(surface, bounds=BOX, resolution=24)
    counts: list[int] = []
    timer = interrupt_after(1.5)
    try:
        with pytest.raises(KeyboardInterrupt):
            # Level 5 has 2.5 million new vertices against 3,000 centres: seconds of Newton steps.
            im.subdivide(control.vertices, control.faces, levels=5, field=surface, progress=counts.append)
    finally:
        timer.cancel()
    assert counts, "no progress was reported before the interrupt"
    assert counts == sorted(counts)
    assert counts[-1] < len(control.faces) * 4**5
    levels = im.subdivide(control.vertices, control.faces, levels=1, field=surface)
    assert levels[1].to_trimesh().is_watertight


@pytest.fixture(scope="module")
def scan():
    """10⁵ points with normals on a sphere: a partition fit of several seconds."""
    return im.shapes.fibonacci_sphere(100_000)


def test_partition_fit_reports_progress(scan):
    p, n = scan
    counts: list[int] = []
    s = im.VariationalSurface.fit(p[:4000], n[:4000], method="partition", progress=counts.append, exact=True)
    assert s.method == "partition"
    assert counts == sorted(counts)
    # Every constraint is inside at least one patch: the count reaches the constraints.
    assert counts[-1] >= 2 * 4000


def test_ctrl_c_stops_a_partition_fit(scan):
    p, n = scan
    timer = interrupt_after(0.5)
    try:
        with pytest.raises(KeyboardInterrupt):
            im.VariationalSurface.fit(p, n, method="partition", exact=True)
    finally:
        timer.cancel()
    # The next fit works.
    s = im.VariationalSurface.fit(p[::50], n[::50], exact=True)
    assert np.abs(s.evaluate(p[::50])).max() < 1e-6


def test_fit_progress_must_be_a_bool_or_callable(scan):
    p, n = scan
    with pytest.raises(ValueError, match="progress"):
        im.VariationalSurface.fit(p[:50], n[:50], progress="yes", exact=True)


def test_global_fit_reports_progress(scan):
    # The factorization reports the columns of the system's null-space block it has done:
    # all 2·1500 − 4 of them by the end, in steps.
    p, n = scan
    counts: list[int] = []
    s = im.VariationalSurface.fit(p[:1500], n[:1500], method="global", progress=counts.append, exact=True)
    assert s.method == "global"
    assert counts == sorted(counts)
    assert counts[-1] == 2 * 1500 - 4


def test_ctrl_c_stops_a_global_fit(scan):
    p, n = scan
    counts: list[int] = []
    timer = interrupt_after(1.0)
    try:
        with pytest.raises(KeyboardInterrupt):
            im.VariationalSurface.fit(p[:4000], n[:4000], method="global", progress=counts.append, exact=True)
    finally:
        timer.cancel()
    assert not counts or counts[-1] < 2 * 4000 - 4
    s = im.VariationalSurface.fit(p[::100], n[::100], method="global", exact=True)
    assert np.abs(s.evaluate(p[::100])).max() < 1e-6


def test_ctrl_c_stops_a_long_evaluation(surface):
    # 2·10⁶ points against 3,000 centres: seconds of work in batches of 65,536 points.
    q = np.random.default_rng(0).uniform(-1, 1, (2_000_000, 3))
    timer = interrupt_after(0.3)
    try:
        with pytest.raises(KeyboardInterrupt):
            surface.evaluate(q)
    finally:
        timer.cancel()
    # The same values as before, batch by batch.
    small = q[:100_000]
    assert np.array_equal(surface.evaluate(small)[:1000], surface.evaluate(small[:1000]))
