"""Options objects: the settings of one polygonizer (:class:`OctreeOptions`,
:class:`TrackingOptions`, for :func:`implicitmesh.polygonize`'s ``options=``), of the
partition fit (:class:`PartitionOptions`, for the fits' ``partition_options=``) or of
anisotropic particle kernels (:class:`AnisotropyOptions`, for
:meth:`BlobField.from_particles`'s ``anisotropic=``), each mirroring the core's settings of the
same name."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["OctreeOptions", "TrackingOptions", "PartitionOptions", "AnisotropyOptions"]


@dataclass(frozen=True)
class OctreeOptions:
    """Settings of ``method="octree"`` (the core's ``OctreeSettings``), for :func:`polygonize`'s
    ``options=``; the same as its keywords ``start_level``, ``safety`` and ``corner_test``.

    Parameters
    ----------
    start_level : int, optional
        Level of the first rejection test (non-negative; 1 tests the root's eight octants).
        Default: the first level whose blocks span at most 1/8 of the lattice's longest side.
    safety : float, optional
        Factor on the circumradius in the rejection test ``|f(centre)| > safety × r``. Default
        1.0, for a :class:`BlobField` a bound on ``|∇f|``.
    corner_test : bool, optional
        Also decide blocks and leaf cells with the values already known. Default True; False
        samples exactly as Cuno et al. §4.3.
    """

    start_level: int | None = None
    safety: float | None = None
    corner_test: bool | None = None

    def keywords(self) -> dict[str, Any]:
        """The settings as :func:`polygonize`'s keywords."""
        return {"start_level": self.start_level, "safety": self.safety, "corner_test": self.corner_test}


@dataclass(frozen=True)
class TrackingOptions:
    """Settings of ``method="tracking"`` (the core's ``TrackingSettings``), for
    :func:`polygonize`'s ``options=``; the same as its keyword ``seeds``.

    Parameters
    ----------
    seeds : (K, 3) array_like of float, optional
        Points inside or on each component of the surface to walk from. Default: the
        primitives' centres of a :class:`BlobField`, the data points of a
        :class:`VariationalSurface`; required for callables.
    """

    seeds: Any = None

    def keywords(self) -> dict[str, Any]:
        """The settings as :func:`polygonize`'s keywords."""
        return {"seeds": self.seeds}


@dataclass(frozen=True)
class AnisotropyOptions:
    """Anisotropic kernels for :meth:`BlobField.from_particles` (``anisotropic=``; the core's
    ``AnisotropySettings``, after Yu & Turk 2013, whose names they keep). Each left None takes
    the default.

    Parameters
    ----------
    neighbour_radius : float, optional
        Radius of the neighbourhood whose weighted covariance shapes a kernel, as a multiple of
        the kernel's support H. Default 2.0 (Yu & Turk's).
    k_r : float, optional
        Largest ratio of a kernel's longest axis to its shortest (1 to 100). Default 4.
    k_s : float, optional
        A stretched kernel's longest axis as a multiple of H (inside the fluid the kernels are
        about round, of support k_s·H). Default 1.
    k_n : float, optional
        Radius of the round kernel of a particle with too few neighbours, as a multiple of H.
        Default 0.5.
    min_neighbours : int, optional
        N_ε: fewer neighbours than this (the particle not counted) give a round kernel.
        Default 25.
    smoothing : float, optional
        λ in [0, 1]: how far each kernel's centre moves to its neighbours' weighted mean.
        Default 0.9. The smoothed centres move surfaces inwards (see the particles doc).
    """

    neighbour_radius: float | None = None
    k_r: float | None = None
    k_s: float | None = None
    k_n: float | None = None
    min_neighbours: int | None = None
    smoothing: float | None = None


#: The options class of each method that has settings of its own.
_METHOD_OPTIONS: dict[str, type[OctreeOptions] | type[TrackingOptions]] = {"octree": OctreeOptions, "tracking": TrackingOptions}


def _method_keywords(method: Any, options: Any, given: dict[str, Any]) -> dict[str, Any]:
    """The per-method keywords for the core: ``given`` (the flat keywords, None when not
    given), or those of ``options`` (an :class:`OctreeOptions` or :class:`TrackingOptions`
    for ``method``), checked: a ValueError names ``options`` when it is of the wrong class or
    given with flat keywords, and ``start_level``, ``safety`` or ``corner_test`` when of the
    wrong type (the core refuses the ones that do not apply to ``method``)."""
    if options is not None:
        wanted = _METHOD_OPTIONS.get(method.lower()) if isinstance(method, str) else None
        if wanted is None or not isinstance(options, (OctreeOptions, TrackingOptions)) or not isinstance(options, wanted):
            expected = f"{wanted.__name__} for method={method!r}" if wanted else f"None for method={method!r}"
            raise ValueError(f"options: expected {expected}, got {type(options).__name__}")
        flat = sorted(k for k, v in given.items() if v is not None)
        if flat:
            raise ValueError(f"options: given with the keywords {flat}; pass these in options only")
        given = dict(given, **options.keywords())
    start_level, safety, corner_test = given.get("start_level"), given.get("safety"), given.get("corner_test")
    if start_level is not None and (
        isinstance(start_level, bool) or not isinstance(start_level, (int, np.integer)) or start_level < 0
    ):
        raise ValueError(f"start_level: must be a non-negative integer, got {start_level!r}")
    if safety is not None and (isinstance(safety, bool) or not isinstance(safety, (int, float, np.floating, np.integer))):
        raise ValueError(f"safety: must be a positive number, got {safety!r}")
    if corner_test is not None and not isinstance(corner_test, (bool, np.bool_)):
        raise ValueError(f"corner_test: must be True or False, got {corner_test!r}")
    return given


class PartitionOptions(dict):
    """The partition fit's patch sizes (the core's ``PartitionSettings``), for
    ``partition_options=`` of :meth:`VariationalSurface.fit`, :meth:`~VariationalSurface.from_mesh`
    and :meth:`~VariationalSurface.interpolate`. Only the settings given are set; the others
    keep the core's defaults. (It is a ``dict`` of the settings given, which the fits read; a
    plain ``dict`` with these keys is taken too.)

    Parameters
    ----------
    max_per_leaf : int, optional
        The octree splits leaves holding more constraints (default 64, at least 8).
    max_patch : int, optional
        And leaves whose patch would hold more (default 256).
    min_points : int, optional
        Smaller patches complete their system with constraints from further away (default 128).
    overlap : float, optional
        A patch's radius over its leaf's half-diagonal (default 1.15).

    Raises
    ------
    ValueError
        Naming the setting when it is not an integer (``overlap``: a number); the fit checks
        the ranges.

    Examples
    --------
    >>> surface = VariationalSurface.fit(points, normals, method="partition",
    ...                                  partition_options=PartitionOptions(max_patch=128))
    """

    _INTEGERS = ("max_per_leaf", "max_patch", "min_points")

    def __init__(
        self,
        *,
        max_per_leaf: int | None = None,
        max_patch: int | None = None,
        min_points: int | None = None,
        overlap: float | None = None,
    ) -> None:
        given = {"max_per_leaf": max_per_leaf, "max_patch": max_patch, "min_points": min_points, "overlap": overlap}
        for name, value in given.items():
            if value is None:
                continue
            number = (int, np.integer) if name in self._INTEGERS else (int, float, np.integer, np.floating)
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, number):
                kind = "an integer" if name in self._INTEGERS else "a number"
                raise ValueError(f"{name}: must be {kind}, got {value!r}")
        super().__init__({k: v for k, v in given.items() if v is not None})

    def __getattr__(self, name: str) -> Any:
        if name in ("max_per_leaf", "max_patch", "min_points", "overlap"):
            return self.get(name)
        raise AttributeError(name)

    def __repr__(self) -> str:
        return f"PartitionOptions({', '.join(f'{k}={v!r}' for k, v in self.items())})"
