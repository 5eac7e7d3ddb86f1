"""Pictures of meshes: a matplotlib renderer that needs no graphics system (used by the demo),
and a pyvista one for notebooks (needs the ``viz`` extra and an off-screen OpenGL; see README)."""

from __future__ import annotations

from os import PathLike

import numpy as np

from .mesh import Mesh

__all__ = ["render_png", "render_pyvista"]


def render_png(
    mesh: Mesh,
    path: str | PathLike[str],
    *,
    title: str | None = None,
    size: tuple[int, int] = (800, 700),
    elev: float = 25.0,
    azim: float = 35.0,
) -> None:
    """Renders a shaded picture of ``mesh`` to a PNG with matplotlib (Agg, off screen).

    Parameters
    ----------
    mesh : Mesh
    path : str or path-like
    title : str, optional
    size : (int, int)
        Pixels (width, height).
    elev, azim : float
        Camera elevation and azimuth in degrees.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    tri = mesh.vertices[mesh.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    e, a = np.radians(elev), np.radians(azim)
    view = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    light = view + np.array([0.3, -0.4, 0.6])
    light /= np.linalg.norm(light)
    shade = 0.25 + 0.75 * np.clip(n @ light, 0, 1)
    base = np.array([0.35, 0.55, 0.85])
    colors = np.clip(shade[:, None] * base[None, :], 0, 1)

    dpi = 100
    fig = plt.figure(figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi)
    ax = fig.add_subplot(projection="3d")
    ax.add_collection3d(Poly3DCollection(tri, facecolors=colors, edgecolors="none", linewidths=0))
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    c, r = (lo + hi) / 2, (hi - lo).max() / 2
    ax.set_xlim(c[0] - r, c[0] + r)
    ax.set_ylim(c[1] - r, c[1] + r)
    ax.set_zlim(c[2] - r, c[2] + r)
    ax.set_box_aspect((1, 1, 1), zoom=1.45)
    ax.view_init(elev=elev, azim=azim)
    ax.set_axis_off()
    if title:
        ax.set_title(title)
    fig.tight_layout()
    fig.savefig(str(path))
    plt.close(fig)


def render_pyvista(
    mesh: Mesh,
    path: str | PathLike[str] | None = None,
    *,
    size: tuple[int, int] = (800, 600),
    smooth: bool = True,
    show_edges: bool = False,
    color: str = "lightsteelblue",
):
    """Renders ``mesh`` off screen with pyvista; writes a PNG when ``path`` is given and returns
    the image as an (H, W, 3) uint8 array."""
    import pyvista as pv

    pv.OFF_SCREEN = True
    p = pv.Plotter(off_screen=True, window_size=list(size))
    p.add_mesh(mesh.to_pyvista(), color=color, smooth_shading=smooth, show_edges=show_edges)
    p.camera_position = "iso"
    img = p.screenshot(str(path) if path is not None else None, return_img=True)
    p.close()
    return img
