"""Type stubs for the Rust extension module (``src/python/``), hand-written and checked against
the built module by ``python -m mypy.stubtest implicitmesh._core`` in CI (``.ci/run``): a name,
a parameter or a default that differs fails it. Return types and property types are not checked
by stubtest; they were checked by hand against the running module."""

from typing import Any, Callable, Literal, Sequence, TypedDict, final

import numpy as np
import numpy.typing as npt
from typing_extensions import Unpack

__all__ = [
    "__version__",
    "DEFAULT_MEMORY_LIMIT",
    "VariationalSurface",
    "BlobField",
    "Tessellator",
    "polygonize",
    "lattice",
    "project_mesh",
    "small_bodies",
    "weld_tiles",
    "StreamedWeld",
    "WeldPlan",
    "write_welded_tile",
    "subdivide",
    "butterfly",
    "ray_cast",
    "closest_points",
    "k_nearest",
    "pca_normals",
    "estimate_normals",
    "_panic_in_worker",
]

__version__: str
#: Bytes a fit or a polygonization may estimate to need when no ``memory_limit`` is given (8 GiB).
DEFAULT_MEMORY_LIMIT: int

_ArrayLike = npt.ArrayLike
_Kernel = Literal["triharmonic", "biharmonic", "thin_plate"]
_FitMethod = Literal["auto", "global", "partition"]

class _FitOptions(TypedDict, total=False):
    """The keywords every fit takes; defaults: ``kernel="triharmonic"``, ``smoothing=0.0``,
    ``memory_limit=None`` (8 GiB), ``method="auto"``, ``progress=None``,
    ``partition_options=None``, ``merge_distance=None`` (0.1 % of the data's typical spacing)."""

    kernel: _Kernel
    smoothing: float
    memory_limit: int | None
    method: _FitMethod
    progress: bool | Callable[[int], object] | None
    partition_options: dict[str, int | float] | None
    merge_distance: float | None

@final
class VariationalSurface:
    @staticmethod
    def fit(
        points: _ArrayLike,
        normals: _ArrayLike | None = None,
        *,
        exact: bool = False,
        viewpoints: _ArrayLike | None = None,
        d: float | None = None,
        w: float | None = None,
        tolerance: float | None = None,
        **options: Unpack[_FitOptions],
    ) -> VariationalSurface: ...
    @staticmethod
    def from_mesh(
        vertices: _ArrayLike,
        faces: _ArrayLike,
        *,
        d: float | None = None,
        w: float | None = None,
        **options: Unpack[_FitOptions],
    ) -> VariationalSurface: ...
    @staticmethod
    def interpolate(
        points: _ArrayLike,
        values: _ArrayLike,
        *,
        tolerance: float | None = None,
        **options: Unpack[_FitOptions],
    ) -> VariationalSurface: ...
    def evaluate(self, points: _ArrayLike) -> npt.NDArray[np.float64]: ...
    def gradient(self, points: _ArrayLike) -> npt.NDArray[np.float64]: ...
    def __call__(self, points: _ArrayLike) -> npt.NDArray[np.float64]: ...
    def __len__(self) -> int: ...
    def to_state(self) -> dict[str, Any]: ...
    def distance_to_data(self, points: _ArrayLike) -> npt.NDArray[np.float64]: ...
    def owned_vertices(self, vertices: _ArrayLike, faces: _ArrayLike) -> tuple[npt.NDArray[np.bool_], int]: ...
    def _cut(self, bounds: _ArrayLike) -> VariationalSurface: ...
    @staticmethod
    def from_state(state: dict[str, Any]) -> VariationalSurface: ...
    def __reduce__(self) -> tuple[Callable[[dict[str, Any]], VariationalSurface], tuple[dict[str, Any]]]: ...
    @property
    def centers(self) -> npt.NDArray[np.float64]: ...
    @property
    def weights(self) -> npt.NDArray[np.float64]: ...
    @property
    def polynomial(self) -> npt.NDArray[np.float64]: ...
    @property
    def constraints(self) -> dict[str, Any]: ...
    @property
    def kernel(self) -> str: ...
    @property
    def method(self) -> Literal["global", "partition"]: ...
    @property
    def patches(self) -> dict[str, npt.NDArray[Any]]: ...
    @property
    def residual(self) -> float: ...
    @property
    def merged_points(self) -> int: ...
    @property
    def reduction(self) -> dict[str, int | float] | None: ...
    @property
    def bounds(self) -> npt.NDArray[np.float64]: ...
    @property
    def outliers(self) -> npt.NDArray[np.int64] | None: ...
    @property
    def report(self) -> dict[str, int | float | bool] | None: ...

@final
class BlobField:
    def __new__(
        cls,
        centers: _ArrayLike,
        radii: float | _ArrayLike,
        strengths: float | _ArrayLike | None = None,
        threshold: float = 0.5,
        *,
        voxel_size: float | None = None,
        kernel: str = "triquet",
        precision: str = "double",
        shapes: _ArrayLike | None = None,
    ) -> BlobField: ...
    @staticmethod
    def from_particles(
        particles: _ArrayLike,
        particle_radius: float,
        *,
        smoothing_length: float = 2.0,
        iso_surface_threshold: float = 0.6,
        kernel: str = "cubic_spline",
        voxel_size: float | None = None,
        precision: str = "double",
        anisotropic: Any = None,
        progress: bool | Callable[[int], object] | None = None,
    ) -> BlobField: ...
    def update(
        self,
        centers: _ArrayLike,
        radii: float | _ArrayLike | None = None,
        strengths: float | _ArrayLike | None = None,
    ) -> None: ...
    def evaluate(self, points: _ArrayLike) -> npt.NDArray[np.float64]: ...
    def potential(self, points: _ArrayLike) -> npt.NDArray[np.float64]: ...
    def gradient(self, points: _ArrayLike) -> npt.NDArray[np.float64]: ...
    def __call__(self, points: _ArrayLike) -> npt.NDArray[np.float64]: ...
    def __len__(self) -> int: ...
    def __getnewargs_ex__(self) -> tuple[tuple[Any, ...], dict[str, Any]]: ...
    def _tile_primitives(
        self,
        origin: _ArrayLike,
        cell: _ArrayLike,
        cells: Sequence[int],
        tile: Sequence[int],
        margin: float,
    ) -> tuple[npt.NDArray[np.uint32], npt.NDArray[np.int64]]: ...
    def _cut(self, bounds: _ArrayLike, margin: float) -> BlobField | None: ...
    def _subset(self, index: npt.NDArray[np.uint32]) -> BlobField: ...
    @property
    def centers(self) -> npt.NDArray[np.float64]: ...
    @property
    def radii(self) -> npt.NDArray[np.float64]: ...
    @property
    def shapes(self) -> npt.NDArray[np.float64] | None: ...
    @property
    def reaches(self) -> npt.NDArray[np.float64]: ...
    @property
    def strengths(self) -> npt.NDArray[np.float64]: ...
    @property
    def threshold(self) -> float: ...
    @property
    def kernel(self) -> str: ...
    @property
    def precision(self) -> str: ...
    @property
    def voxel_size(self) -> float: ...
    @property
    def voxel_dims(self) -> list[int]: ...
    @property
    def bounds(self) -> npt.NDArray[np.float64]: ...

_Field = VariationalSurface | BlobField | Callable[[npt.NDArray[np.float64]], _ArrayLike]
_MeshTuple = tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], npt.NDArray[np.float64], dict[str, Any]]

class _PolygonizeOptions(TypedDict, total=False):
    """The keywords every polygonizer takes; defaults: ``ambiguity="separate"``,
    ``normals=True``, ``batch_size=262144``, ``memory_limit=None`` (8 GiB), ``progress=None``."""

    ambiguity: str
    normals: bool
    batch_size: int
    memory_limit: int | None
    progress: Callable[[int], object] | None

@final
class Tessellator:
    def __new__(cls) -> Tessellator: ...
    def polygonize(
        self,
        field: _Field,
        bounds: _ArrayLike,
        resolution: int | Sequence[int],
        *,
        seeds: _ArrayLike | None = None,
        blocks: bool = True,
        **options: Unpack[_PolygonizeOptions],
    ) -> _MeshTuple: ...
    @property
    def capacity_bytes(self) -> int: ...

def polygonize(
    field: _Field,
    bounds: _ArrayLike,
    resolution: int | Sequence[int],
    *,
    method: str = "dense",
    project: bool = False,
    start_level: int | None = None,
    safety: float | None = None,
    corner_test: bool | None = None,
    seeds: _ArrayLike | None = None,
    window: _ArrayLike | None = None,
    boundary: bool = False,
    **options: Unpack[_PolygonizeOptions],
) -> tuple[
    npt.NDArray[np.float64],
    npt.NDArray[np.int64] | npt.NDArray[np.uint32],
    npt.NDArray[np.float64],
    dict[str, Any],
    npt.NDArray[np.uint32] | None,
    npt.NDArray[np.uint64] | None,
]: ...

def lattice(bounds: _ArrayLike, resolution: int | Sequence[int]) -> tuple[list[int], list[float], list[float]]: ...
def project_mesh(field: _Field, bounds: _ArrayLike, resolution: int | Sequence[int], vertices: _ArrayLike, faces: _ArrayLike, *, normals: bool = True, batch_size: int = 262144, progress: Callable[[int], object] | None = None) -> _MeshTuple: ...
def small_bodies(vertices: _ArrayLike, faces: _ArrayLike, particles: _ArrayLike, min_particles: int) -> tuple[npt.NDArray[np.bool_], int, int]: ...
def weld_tiles(
    tiles: Sequence[tuple[_ArrayLike, _ArrayLike, _ArrayLike, _ArrayLike, _ArrayLike, _ArrayLike]],
    cells: Sequence[int],
    origin: Sequence[float],
    cell: Sequence[float],
    *,
    progress: Callable[[int], object] | None = None,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], npt.NDArray[np.float64]]: ...

@final
class StreamedWeld:
    """Tile meshes welded one at a time, in window order, into the mesh ``weld_tiles`` makes."""

    def __new__(cls, tiles: int, cells: Sequence[int], origin: Sequence[float], cell: Sequence[float], normals: bool | None = None, memory_limit: int | None = None) -> StreamedWeld: ...
    def add(self, window: _ArrayLike, vertices: _ArrayLike, faces: _ArrayLike, normals: _ArrayLike, boundary: _ArrayLike, keys: _ArrayLike) -> None: ...
    @property
    def added(self) -> int: ...
    @property
    def vertices(self) -> int: ...
    def result(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], npt.NDArray[np.float64]]: ...

@final
class WeldPlan:
    """Where each tile's rows go in the welded mesh, from its counts and boundary vertices alone."""

    def __new__(cls, cells: Sequence[int], origin: Sequence[float], cell: Sequence[float], normals: bool, memory_limit: int | None = None) -> WeldPlan: ...
    def add(self, window: _ArrayLike, vertices: int, faces: int, boundary: _ArrayLike, keys: _ArrayLike, positions: _ArrayLike) -> tuple[int, int, npt.NDArray[np.uint32]]: ...
    @property
    def added(self) -> int: ...
    @property
    def vertices(self) -> int: ...
    @property
    def faces(self) -> int: ...

def write_welded_tile(vertices: _ArrayLike, faces: _ArrayLike, normals: _ArrayLike, first_vertex: int, joined: _ArrayLike, out_vertices: npt.NDArray[np.float64], out_faces: npt.NDArray[np.int64], out_normals: npt.NDArray[np.float64] | None = None) -> None: ...

def subdivide(field: _Field, vertices: _ArrayLike, faces: _ArrayLike, levels: int, *, tolerance: float | None = None, max_steps: int | None = None, step: float | None = None, progress: Callable[[int], object] | None = None) -> list[_MeshTuple]: ...
def butterfly(vertices: _ArrayLike, faces: _ArrayLike, levels: int, w: float, *, progress: Callable[[int], object] | None = None) -> list[tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], npt.NDArray[np.float64]]]: ...

def ray_cast(vertices: _ArrayLike, faces: _ArrayLike, origins: _ArrayLike, directions: _ArrayLike) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]: ...
def closest_points(vertices: _ArrayLike, faces: _ArrayLike, points: _ArrayLike) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.int64]]: ...
def k_nearest(points: _ArrayLike, k: int, queries: _ArrayLike | None = None) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]: ...
def pca_normals(points: _ArrayLike, k: int = 20) -> npt.NDArray[np.float64]: ...
def estimate_normals(points: _ArrayLike, neighbours: int = 20, viewpoints: _ArrayLike | None = None, progress: Callable[[int], object] | None = None) -> tuple[npt.NDArray[np.float64], dict[str, int]]: ...

# Testing only: panics inside a rayon worker of the interruptible runner (or on the calling thread
# with on_caller=True); raises RuntimeError naming "_panic_in_worker" (tests/test_extreme.py).
def _panic_in_worker(on_caller: bool = False) -> None: ...
