"""Saving fitted fields to ``.npz`` files and loading them back, without fitting again.

Fields also pickle (``pickle.dumps(surface)``), which is what multiprocessing and Dask use; an
``.npz`` file holds only numpy arrays and numbers (it is read with ``allow_pickle=False``), so it
is safe to load from untrusted sources and readable by any numpy.
"""

from __future__ import annotations

import os
from typing import Any, Union

import numpy as np

from ._core import BlobField, VariationalSurface

__all__ = ["save", "load"]

Field = Union[VariationalSurface, BlobField]


def _state(field: Field) -> dict[str, Any]:
    if isinstance(field, VariationalSurface):
        return {"field": "VariationalSurface", **field.to_state()}
    if isinstance(field, BlobField):
        (centers, radii, strengths, threshold), kwargs = field.__getnewargs_ex__()
        state = {
            "field": "BlobField",
            "centers": centers,
            "radii": radii,
            "strengths": strengths,
            "threshold": threshold,
            "voxel_size": kwargs["voxel_size"],
            "kernel": kwargs["kernel"],
            "precision": kwargs["precision"],
        }
        if kwargs["shapes"] is not None:
            state["shapes"] = kwargs["shapes"]
        return state
    raise ValueError(f"field: expected a VariationalSurface or a BlobField, got {type(field).__name__}")


def save(path: str | os.PathLike[str], field: Field) -> None:
    """Writes a fitted field to an ``.npz`` file that :func:`load` reads back.

    Parameters
    ----------
    path : str or path-like
        The file to write (numpy appends ``.npz`` when the name has no suffix).
    field : VariationalSurface or BlobField
        The field; the one :func:`load` returns evaluates to the same bits.

    Raises
    ------
    ValueError
        For anything but a :class:`VariationalSurface` or a :class:`BlobField`.
    """
    state = _state(field)
    np.savez(path, **{k: np.asarray(v) for k, v in state.items()})


def load(path: str | os.PathLike[str]) -> Field:
    """Reads a field that :func:`save` wrote.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    VariationalSurface or BlobField

    Raises
    ------
    ValueError
        For a file :func:`save` did not write (missing or inconsistent arrays).
    """
    with np.load(path, allow_pickle=False) as f:
        state = {k: (f[k].item() if f[k].ndim == 0 else f[k]) for k in f.files}
    kind = state.pop("field", None)
    if kind == "VariationalSurface":
        return VariationalSurface.from_state(state)
    if kind == "BlobField":
        return BlobField(
            state["centers"],
            state["radii"],
            state["strengths"],
            state["threshold"],
            voxel_size=state["voxel_size"],
            kernel=state.get("kernel", "triquet"),
            precision=state.get("precision", "double"),
            shapes=state.get("shapes"),
        )
    raise ValueError(f"path: {os.fspath(path)!r} does not hold a field written by implicitmesh.save")
