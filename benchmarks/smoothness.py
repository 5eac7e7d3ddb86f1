"""How smooth a fluid surface is on the flat parts of a pool, and the volume it encloses.

The flat parts are chosen from the **particles**, so every method's mesh of one frame is measured
on the same patches (a smoothing method cannot change what counts as flat):

1. The particles are binned into vertical columns of side 2r (the particle spacing, r the particle
   radius); each column's top is the height of its highest particle.
2. Patch centres lie on a square grid of spacing ``patch`` (default 10 r). A centre is a flat
   patch when every column within ``patch / 2 + 2r`` of it holds particles (no hole, no edge of
   the fluid), the columns' tops fit a plane tilted at most ``max_tilt`` degrees from horizontal
   with no top further than 2r from it (no wave crest, splash or droplet on it), each column is
   filled from the floor to its top (at least ``fill`` of the particles a column of that height
   holds at rest: not a sheet or droplet above air), and the centre lies at least ``wall_margin``
   (default 20 r) inside the walls (``walls``, or the particles' horizontal bounding box).
3. On a mesh, a patch's faces are those whose centroid lies within ``patch / 2`` of the centre
   horizontally, between 2r below and 4r above the particles' top plane, and faces up (normal's z
   component > 0).

On each patch: a least-squares plane through the faces' vertices, and the vertices' distances to
it; :func:`smoothness` reports the root mean square of those distances over all patches (in units
of r) and the mean angle between the normals of neighbouring faces (both in a patch, sharing an
edge), in degrees. :func:`enclosed_volume` is the divergence theorem's volume of a closed mesh.

The metrics use numpy only (scipy is not needed).
"""

from __future__ import annotations

import numpy as np

#: Default patch diameter, in particle radii.
PATCH = 10.0
#: Default distance of a patch centre from the walls, in particle radii.
WALL_MARGIN = 20.0


def flat_patches(particles, radius: float, *, patch: float | None = None, max_tilt: float = 10.0,
                 fill: float = 0.7, walls=None, wall_margin: float | None = None, floor: float | None = None):
    """The flat patches of a pool of particles (z up), see the module's description.

    Parameters
    ----------
    particles : (N, 3) float64
        Particle centres, z up.
    radius : float
        The particle radius r (particles are 2r apart at rest).
    patch : float, optional
        Patch diameter (default 10 r).
    max_tilt : float
        Largest tilt of a patch's plane from horizontal, in degrees.
    fill : float
        Fraction of a full column's particles a column must hold.
    walls : ((x0, y0), (x1, y1)), optional
        The container's walls (default: the particles' horizontal bounding box).
    wall_margin : float, optional
        Least distance of a patch centre from the walls (default 20 r).
    floor : float, optional
        The floor's height (default: the lowest particle's height less r).

    Returns
    -------
    patches : (K, 5) float64
        Per patch: centre x, y and the particles' top plane z = a x + b y + c as (a, b, c).
    """
    p = np.asarray(particles, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError("particles must be an (N, 3) array")
    if not radius > 0:
        raise ValueError("radius must be positive")
    h = 2.0 * radius
    d = PATCH * radius if patch is None else float(patch)
    margin = WALL_MARGIN * radius if wall_margin is None else float(wall_margin)
    lo_w, hi_w = (p[:, :2].min(axis=0), p[:, :2].max(axis=0)) if walls is None else map(np.asarray, walls)
    z0 = p[:, 2].min() - radius if floor is None else float(floor)

    lo = p[:, :2].min(axis=0)
    ij = np.floor((p[:, :2] - lo) / h).astype(np.int64)
    shape = ij.max(axis=0) + 1
    flat = ij[:, 0] * shape[1] + ij[:, 1]
    count = np.bincount(flat, minlength=shape[0] * shape[1]).reshape(shape)
    top = np.full(shape[0] * shape[1], -np.inf)
    np.maximum.at(top, flat, p[:, 2])
    top = top.reshape(shape)
    centres_x = lo[0] + (np.arange(shape[0]) + 0.5) * h
    centres_y = lo[1] + (np.arange(shape[1]) + 0.5) * h

    reach = 0.5 * d + h
    k = int(np.ceil(reach / h))
    offsets = [(a, b) for a in range(-k, k + 1) for b in range(-k, k + 1) if np.hypot(a * h, b * h) <= reach]
    out = []
    for cx in np.arange(lo_w[0] + margin, hi_w[0] - margin + 1e-12, d):
        for cy in np.arange(lo_w[1] + margin, hi_w[1] - margin + 1e-12, d):
            i0, j0 = int(np.floor((cx - lo[0]) / h)), int(np.floor((cy - lo[1]) / h))
            ii = np.array([i0 + a for a, _ in offsets])
            jj = np.array([j0 + b for _, b in offsets])
            if ii.min() < 0 or jj.min() < 0 or ii.max() >= shape[0] or jj.max() >= shape[1]:
                continue
            c, t = count[ii, jj], top[ii, jj]
            if (c == 0).any():
                continue
            if (c < fill * (t - z0) / h).any():
                continue
            x, y = centres_x[ii], centres_y[jj]
            a = np.stack([x, y, np.ones_like(x)], axis=1)
            coef = np.linalg.lstsq(a, t, rcond=None)[0]
            if np.degrees(np.arctan(np.hypot(coef[0], coef[1]))) > max_tilt:
                continue
            if np.abs(a @ coef - t).max() > h:
                continue
            out.append([cx, cy, *coef])
    return np.asarray(out, dtype=np.float64).reshape(-1, 5)


def face_normals(vertices, faces):
    """Unit normals and areas of the faces."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    length = np.linalg.norm(n, axis=1)
    return n / np.maximum(length, 1e-300)[:, None], 0.5 * length


def enclosed_volume(vertices, faces) -> float:
    """The volume a closed, outward-oriented mesh encloses (divergence theorem)."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def neighbour_angles(faces, normals, keep) -> np.ndarray:
    """Angles (degrees) between the normals of faces that share an edge, both faces in ``keep``
    (a boolean mask over the faces)."""
    f = np.asarray(faces, dtype=np.int64)
    index = np.flatnonzero(keep)
    if len(index) == 0:
        return np.zeros(0)
    e = np.concatenate([f[index][:, [0, 1]], f[index][:, [1, 2]], f[index][:, [2, 0]]])
    owner = np.concatenate([index, index, index])
    e.sort(axis=1)
    order = np.lexsort((e[:, 1], e[:, 0]))
    e, owner = e[order], owner[order]
    same = (e[1:] == e[:-1]).all(axis=1)
    a, b = owner[:-1][same], owner[1:][same]
    cos = np.clip(np.einsum("ij,ij->i", normals[a], normals[b]), -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def smoothness(vertices, faces, patches, radius: float, patch: float | None = None) -> dict:
    """Smoothness of a mesh on the flat ``patches`` of :func:`flat_patches` (same ``patch``).

    Returns
    -------
    dict
        ``plane_rms_r``: root mean square distance of the patches' vertices from each patch's own
        least-squares plane, in units of r; ``normal_angle_deg``: mean angle between the normals of
        neighbouring faces of the patches, in degrees; ``patches``: patches measured (with at least
        three vertices); ``faces``: faces in them.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    d = PATCH * radius if patch is None else float(patch)
    normals, _ = face_normals(v, f)
    centroid = v[f].mean(axis=1)
    keep = np.zeros(len(f), dtype=bool)
    squares, count, measured = 0.0, 0, 0
    for cx, cy, a, b, c in np.asarray(patches, dtype=np.float64).reshape(-1, 5):
        dx, dy = centroid[:, 0] - cx, centroid[:, 1] - cy
        top = a * centroid[:, 0] + b * centroid[:, 1] + c
        dz = centroid[:, 2] - top
        mine = (dx * dx + dy * dy <= (0.5 * d) ** 2) & (dz >= -2 * radius) & (dz <= 4 * radius) & (normals[:, 2] > 0)
        ids = np.unique(f[mine])
        if len(ids) < 3:
            continue
        keep |= mine
        q = v[ids]
        m = np.stack([q[:, 0], q[:, 1], np.ones(len(q))], axis=1)
        coef = np.linalg.lstsq(m, q[:, 2], rcond=None)[0]
        dist = (q[:, 2] - m @ coef) / np.sqrt(1.0 + coef[0] ** 2 + coef[1] ** 2)
        squares += float((dist * dist).sum())
        count += len(q)
        measured += 1
    angles = neighbour_angles(f, normals, keep)
    return {"plane_rms_r": float(np.sqrt(squares / count) / radius) if count else None,
            "normal_angle_deg": float(angles.mean()) if len(angles) else None,
            "patches": measured, "faces": int(keep.sum())}
