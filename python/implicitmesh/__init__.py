"""implicitmesh: implicit surfaces to triangle meshes, with a Rust core.

Fields (negative inside, positive outside):

- :class:`VariationalSurface` — RBF surfaces fitted to points with normals or to a mesh.
- :class:`BlobField` — blobs of point primitives with compact kernels (Triquet et al.).
- any Python callable taking (N, 3) float64 points and returning (N,) values.

Polygonizers: :func:`polygonize` with ``method="dense"`` (plain marching cubes, the reference),
``"sparse"`` (blob fields: blocks the field's bounds cannot rule out), ``"octree"`` (Cuno et al.)
or ``"tracking"`` (Triquet et al.); :class:`Tessellator` keeps the tracking caches between calls
for animation; :class:`OctreeOptions` and :class:`TrackingOptions` hold a method's settings,
:class:`PartitionOptions` the partition fit's. Mesh refinement: :func:`subdivide` (1-to-4 with Newton projection onto the
field, Jin et al.), :func:`butterfly` and :func:`blend`.
Results are :class:`Mesh` objects with numpy arrays that trimesh and pyvista take as they are;
:func:`compare` counts the triangles two meshes do not share; :func:`estimate_normals` gives
points without normals oriented ones. Fitted fields pickle, and
:func:`save` and :func:`load` keep them in ``.npz`` files. :func:`read_particles` reads
simulation frames (``.npy``, ``.npz``, ``.ply``, meshio formats).
"""

from ._core import BlobField, VariationalSurface, __version__
from .mesh import Mesh, compare
from .options import AnisotropyOptions, OctreeOptions, PartitionOptions, TrackingOptions
from .polygonize import METHODS, Ambiguity, Tessellator, polygonize
from . import shapes
from . import scanner
from .normals import estimate_normals
from .subdivision import blend, butterfly, subdivide
from .io import load, save
from .frames import read_particles

__all__ = ["VariationalSurface", "BlobField", "Tessellator", "Mesh", "compare", "polygonize", "Ambiguity", "METHODS", "OctreeOptions", "TrackingOptions", "PartitionOptions", "AnisotropyOptions", "shapes", "estimate_normals", "subdivide", "butterfly", "blend", "save", "load", "read_particles", "__version__"]
