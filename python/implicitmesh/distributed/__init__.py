"""Tiled polygonization on Dask: the lattice cut into tiles of cells, one task per tile, the
tiles' meshes welded into the mesh :func:`implicitmesh.polygonize` makes on one machine.

Every tile is a window of the one lattice (``_core.polygonize(..., window=)``): its lattice
points and edge vertices are computed from the whole lattice's origin and indices, so a vertex on
a face two tiles share is the same number in both. Each tile reports the lattice edges of its
vertices on its boundary faces in the whole lattice's numbering (``boundary=True``), and the
weld joins the vertices of one edge: exact, one vertex per crossed edge as on one machine.

:func:`polygonize` returns the welded mesh; :func:`write_tiles` leaves the tiles in a directory
and :func:`weld` joins them later. The modules, in the order a run uses them:

- ``_plan``: the arguments checked, the tiles, and what each tile receives of the field
  (:func:`cut_field`);
- ``_transport``: how the tiles' meshes come back (``Transport``) and how the cuts reach the
  workers (``SentCuts``), through the files of ``_cut_files`` and ``_tile_files`` on the
  client's machine or through Dask;
- ``_tile``: the task run per tile and its result (``TileResult``);
- ``_weld``: the ``Weld`` protocol and the weld in the client's memory; ``_weld_in_place``: the
  weld written by the workers into shared memory;
- ``_run``: plan, submit, collect and finish.
"""

from ._plan import TILE_METHODS, cut_blobs, cut_field, tile_box, tiles
from ._run import MANIFEST, polygonize, weld, write_tiles

__all__ = ["polygonize", "write_tiles", "weld", "tiles", "tile_box", "cut_field", "cut_blobs", "TILE_METHODS", "MANIFEST"]
