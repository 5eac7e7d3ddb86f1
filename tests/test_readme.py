"""The README's tour runs as written and does what its comments say."""

from __future__ import annotations

import re

import numpy as np
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_tour_runs(tmp_path, monkeypatch):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), re.S)
    assert blocks, "the README has no python example"
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(compile(blocks[0], str(README), "exec"), scope)
    assert scope["vertices"].shape == (800, 3) and scope["faces"].shape == (1600, 3)
    assert scope["surface"].evaluate(scope["vertices"]).__abs__().max() < 1e-9
    assert scope["mesh"].to_trimesh().is_watertight
    assert (tmp_path / "knot.ply").is_file()
    back = scope["im"].load(tmp_path / "knot_fit.npz")
    assert (back.evaluate(scope["vertices"]) == scope["surface"].evaluate(scope["vertices"])).all()
    assert [len(level.faces) for level in scope["levels"]] == [1600, 6400, 25600]
    assert len(scope["frame"].faces) > 0
    scan, scanned, closed = scope["scan"], scope["scanned"], scope["closed"]
    found = np.isin(scan.outliers, scanned.outliers).mean()
    assert found > 0.8, found
    assert closed.to_trimesh().is_watertight and len(closed.to_trimesh().split(only_watertight=False)) == 1
