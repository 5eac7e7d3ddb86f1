"""Pictures of one real frame meshed by each method, for the docs (``docs/images/``).

One frame of :mod:`benchmarks.sph_frames` (default ``dam-break-1e5`` at 1.0 s) meshed by the
methods of :mod:`benchmarks.frame_cases` (those that run here; the anisotropic colour field once the
core has it), each rendered off screen by pyvista with the same camera and light, as
``docs/images/NAME-METHOD.png`` (small PNGs of 128 colours). Off-screen rendering needs EGL or OSMesa (on Debian
``apt-get install libegl1 libgl1-mesa-dri``).

    python -m benchmarks.sph_pictures [--scene NAME] [--time SECONDS] [--out DIR] [--frames DIR]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from benchmarks import frame_cases, sph_frames

ROOT = Path(__file__).resolve().parent.parent
#: Methods drawn, in order.
METHODS = ("colour-f32", "splashsurf-f32", "splashsurf-smooth-f32", "colour-aniso-f32")
#: Picture size in pixels.
SIZE = (640, 380)


def camera(box) -> list:
    """A camera looking from the near side, above the middle of the tank, towards the far wall
    (z up), as pyvista's (position, focal point, view up)."""
    (x0, y0, _), (x1, y1, _) = box
    return [(0.5 * (x0 + x1) - 0.8, y0 - 3.6, 2.3), (0.55 * x1, 0.5 * (y0 + y1), 0.7), (0.0, 0.0, 1.0)]


def render(vertices, faces, box, path: Path, title: str) -> None:
    import numpy as np
    import pyvista as pv

    pv.OFF_SCREEN = True
    f = np.hstack([np.full((len(faces), 1), 3, dtype=np.int64), np.asarray(faces, dtype=np.int64)])
    mesh = pv.PolyData(np.asarray(vertices, dtype=np.float64), f.ravel())
    p = pv.Plotter(off_screen=True, window_size=SIZE)
    p.set_background("white")
    p.add_mesh(mesh, color=(0.55, 0.72, 0.92), smooth_shading=False, specular=0.35, specular_power=25)
    (x0, y0, z0), (x1, y1, _) = box
    floor = pv.Plane(center=(0.5 * (x0 + x1), 0.5 * (y0 + y1), z0), direction=(0, 0, 1), i_size=x1 - x0,
                     j_size=y1 - y0)
    p.add_mesh(floor, color=(0.85, 0.85, 0.82))
    p.add_text(title, font_size=10, color="black", position="upper_left")
    p.camera_position = camera(box)
    p.camera.view_angle = 30
    image = p.screenshot(return_img=True)
    p.close()
    from PIL import Image

    # 128 colours keep the shading and make the file a third of the size.
    Image.fromarray(image).quantize(colors=128).save(path, optimize=True)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", default="dam-break-1e5", choices=sph_frames.SCENES)
    p.add_argument("--time", type=float, default=1.0, help="the frame's simulated time in seconds")
    p.add_argument("--out", default=str(ROOT / "docs" / "images"), metavar="DIR")
    p.add_argument("--frames", default=None, metavar="DIR", help="the frames' cache")
    p.add_argument("--methods", default=",".join(METHODS), help="comma-separated methods")
    a = p.parse_args(argv)
    if a.frames:
        import os

        os.environ[sph_frames.ENV_CACHE] = str(sph_frames.cache_dir(a.frames))
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    particles, info = frame_cases.frame_particles(a.scene, int(round(1000 * a.time)))
    r = float(info["particle_radius"])
    for method in a.methods.split(","):
        try:
            v, f, facts = frame_cases.RECONSTRUCT[method](particles, r)
        except frame_cases.Skipped as e:
            print(f"[sph_pictures] {method} skipped: {e}", file=sys.stderr)
            continue
        path = out / f"{a.scene}-{method}.png"
        render(v, f, info["box"], path, f"{method}: {len(f):,} triangles")
        print(f"[sph_pictures] {path} ({path.stat().st_size // 1024} KiB, {facts['total_s']:.2f} s)",
              file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
