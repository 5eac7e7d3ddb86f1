"""The :class:`Mesh` every polygonizer returns, and its conversions."""

from __future__ import annotations

from dataclasses import dataclass, field
from os import PathLike
from typing import Any

import numpy as np

__all__ = ["Mesh", "compare"]


@dataclass
class Mesh:
    """A triangle mesh made by a polygonizer.

    Attributes
    ----------
    vertices : (V, 3) float64
        Vertex positions.
    faces : (F, 3) int64
        Vertex indices of each triangle, counter-clockwise seen from outside (outward normals).
    normals : (V, 3) float64
        Unit vertex normals from the field's gradient; shape (0, 3) when not computed.
    stats : dict
        What the polygonizer did: ``evaluations`` (field values computed, exact),
        ``lattice_points`` (what plain marching cubes evaluates), ``evaluation_percent``,
        ``normal_evaluations``, ``cells_visited``, ``cells_crossed``, ``cells_per_level``,
        ``seconds`` (per phase and ``total``), ``resolution``, ``method``.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    stats: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.vertices = np.ascontiguousarray(self.vertices, dtype=np.float64).reshape(-1, 3)
        self.faces = np.ascontiguousarray(self.faces, dtype=np.int64).reshape(-1, 3)
        self.normals = np.ascontiguousarray(self.normals, dtype=np.float64).reshape(-1, 3)

    def __repr__(self) -> str:
        return f"Mesh(vertices={len(self.vertices)}, faces={len(self.faces)})"

    @property
    def area(self) -> float:
        """Total surface area."""
        a, b, c = (self.vertices[self.faces[:, k]] for k in range(3))
        return float(0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())

    @property
    def volume(self) -> float:
        """Signed enclosed volume (positive for a closed mesh oriented outward)."""
        a, b, c = (self.vertices[self.faces[:, k]] for k in range(3))
        return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)

    @property
    def euler_number(self) -> int:
        """V − E + F over the vertices used by faces (2 for a sphere, 0 for a torus)."""
        f = self.faces
        if len(f) == 0:
            return 0
        return int(count_distinct(f.ravel()) - count_edges(f) + len(f))

    def to_trimesh(self, process: bool = False):
        """The mesh as a :class:`trimesh.Trimesh` (vertex normals kept; ``process=False`` keeps
        vertices and faces exactly as they are)."""
        import trimesh

        kwargs = {}
        if len(self.normals) == len(self.vertices) and len(self.vertices):
            kwargs["vertex_normals"] = self.normals
        return trimesh.Trimesh(self.vertices, self.faces, process=process, **kwargs)

    def to_pyvista(self):
        """The mesh as a :class:`pyvista.PolyData` with point data ``"Normals"`` (needs the
        ``viz`` extra)."""
        import pyvista as pv

        cells = np.hstack([np.full((len(self.faces), 1), 3, dtype=np.int64), self.faces]).ravel()
        poly = pv.PolyData(self.vertices.copy(), cells)
        if len(self.normals) == len(self.vertices):
            poly.point_data["Normals"] = self.normals
        return poly

    def trimmed(self, keep: np.ndarray) -> "Mesh":
        """The triangles whose three vertices are kept, with only the vertices they use.

        Parameters
        ----------
        keep : (V,) bool
            The vertices to keep.

        Returns
        -------
        Mesh
            Its ``stats`` are this mesh's, with ``triangles`` and ``vertices`` counted again and
            ``trimmed``, the triangles dropped.
        """
        keep = np.asarray(keep, dtype=bool)
        if keep.shape != (len(self.vertices),):
            raise ValueError(f"keep: expected shape ({len(self.vertices)},), got {keep.shape}")
        faces = self.faces[keep[self.faces].all(axis=1)]
        used = np.zeros(len(self.vertices), dtype=bool)
        used[faces.ravel()] = True
        index = np.cumsum(used) - 1
        normals = self.normals[used] if len(self.normals) else self.normals
        stats = dict(self.stats)
        stats.update(triangles=len(faces), vertices=int(used.sum()), trimmed=len(self.faces) - len(faces))
        return Mesh(self.vertices[used], index[faces], normals, stats)

    def save(self, path: str | PathLike[str]) -> None:
        """Writes the mesh; the format follows the suffix (``.ply``, ``.obj``, ``.stl``, ``.off``,
        ``.glb`` … anything trimesh writes)."""
        self.to_trimesh().export(str(path))

    def quality(self) -> dict[str, np.ndarray | float]:
        """Triangle quality: ``min_angle`` (F,) degrees, ``aspect_ratio`` (F,) (longest edge over
        2√3 × inradius; 1 for equilateral), and their means and 5th percentiles."""
        a, b, c = (self.vertices[self.faces[:, k]] for k in range(3))
        la = np.linalg.norm(b - c, axis=1)
        lb = np.linalg.norm(c - a, axis=1)
        lc = np.linalg.norm(a - b, axis=1)

        def angle(opp, s1, s2):
            with np.errstate(invalid="ignore", divide="ignore"):
                cos = (s1**2 + s2**2 - opp**2) / (2 * s1 * s2)
            return np.degrees(np.arccos(np.clip(np.nan_to_num(cos, nan=1.0), -1, 1)))

        min_angle = np.minimum(np.minimum(angle(la, lb, lc), angle(lb, lc, la)), angle(lc, la, lb))
        area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
        s = 0.5 * (la + lb + lc)
        with np.errstate(invalid="ignore", divide="ignore"):
            aspect = np.maximum(np.maximum(la, lb), lc) / (2 * np.sqrt(3) * area / s)
        return {
            "min_angle": min_angle,
            "aspect_ratio": aspect,
            "min_angle_mean": float(min_angle.mean()) if len(min_angle) else float("nan"),
            "min_angle_p5": float(np.percentile(min_angle, 5)) if len(min_angle) else float("nan"),
            "aspect_ratio_mean": float(aspect.mean()) if len(aspect) else float("nan"),
        }


def _distinct(values: np.ndarray) -> np.ndarray:
    """The distinct values of ``values``, sorted (a sort, not numpy's hashing ``unique``, which
    is several times slower on millions of integers)."""
    s = np.sort(values, axis=None)
    first = np.ones(len(s), dtype=bool)
    first[1:] = s[1:] != s[:-1]
    return s[first]


def count_distinct(values: np.ndarray) -> int:
    """The number of distinct integers in ``values``."""
    return len(_distinct(values))


def count_edges(faces: np.ndarray) -> int:
    """The number of distinct undirected edges of (F, 3) ``faces`` of non-negative indices."""
    f = np.asarray(faces, dtype=np.int64)
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    return count_distinct(e[:, 0] * (int(f.max(initial=0)) + 1) + e[:, 1])


def _canonical_triangles(ids: np.ndarray) -> np.ndarray:
    """Rotates each row (a triangle's corner ids) so its smallest id comes first, keeping the
    cyclic order (the orientation)."""
    m = np.argmin(ids, axis=1)
    return np.take_along_axis(ids, (m[:, None] + np.arange(3)) % 3, axis=1)


def _sorted_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``rows`` (n, k) sorted lexicographically: (the order, the sorted rows, whether each
    sorted row differs from the one before it)."""
    order = np.lexsort(rows.T[::-1])
    s = rows[order]
    first = np.ones(len(s), dtype=bool)
    first[1:] = (s[1:] != s[:-1]).any(axis=1)
    return order, s, first


def _triangle_keys(ids: np.ndarray, n: int) -> np.ndarray:
    """(F, 3) corner ids below ``n``, each row rotated to start at its smallest id, as (F, k)
    int64 keys that are equal exactly when the rotated rows are: one key when three ids fit in
    63 bits, else two."""
    t = _canonical_triangles(ids)
    if n <= 1 << 21:
        return ((t[:, 0] << 42) | (t[:, 1] << 21) | t[:, 2])[:, None]
    return np.stack([t[:, 0] * n + t[:, 1], t[:, 2]], axis=1)


def _distinct_rows(rows: np.ndarray) -> np.ndarray:
    """The distinct rows of ``rows`` (n, k), sorted."""
    if rows.shape[1] == 1:
        return _distinct(rows[:, 0])[:, None]
    _, s, first = _sorted_rows(rows)
    return s[first]


def compare(a: Mesh, b: Mesh) -> dict[str, int]:
    """Compares two meshes triangle by triangle, by exact vertex coordinates and orientation.

    Vertices are matched by their exact float64 coordinates, so meshes made by different
    polygonizers on the same lattice compare equal when they contain the same triangles, in
    whatever order and with whatever vertex numbering.

    Parameters
    ----------
    a, b : Mesh

    Returns
    -------
    dict
        ``missing``: triangles of ``a`` not in ``b`` (holes in ``b`` when ``a`` is the dense
        reference); ``extra``: triangles of ``b`` not in ``a``; ``common``: triangles in both.
        Triangles are counted once however often a mesh repeats them.
    """
    # One id per distinct position (coordinate bit patterns) of either mesh's vertices.
    positions = np.concatenate([a.vertices, b.vertices]).view(np.uint64).reshape(-1, 3)
    order, _, first = _sorted_rows(positions)
    ids = np.empty(len(positions), dtype=np.int64)
    ids[order] = np.cumsum(first) - 1
    n = int(np.count_nonzero(first))
    ta = _distinct_rows(_triangle_keys(ids[: len(a.vertices)][a.faces].reshape(-1, 3), n))
    tb = _distinct_rows(_triangle_keys(ids[len(a.vertices) :][b.faces].reshape(-1, 3), n))
    # A triangle in both meshes is one row of each, so two equal rows of the two together.
    both = np.concatenate([ta, tb])
    common = len(both) - len(_distinct_rows(both))
    return {"missing": len(ta) - common, "extra": len(tb) - common, "common": common}
