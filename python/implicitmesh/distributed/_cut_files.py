"""The tiles' cuts of a partition fit or a blob field passed to the workers through files on the
client's machine instead of Dask's comms.

When every worker sees the run's directory (made by the client in shared memory, ``/dev/shm``,
where there is one: see :mod:`._tile_files`), the client writes each tile's cut
(:meth:`VariationalSurface.to_state`, or a blob field's constructor arguments: its arrays in
``.npy`` format one after another, then its other entries as JSON) into a file there, and the
tile's task carries only a :class:`CutFile` naming it; the worker maps the file and builds the
cut from it (:meth:`CutFile.load`).
Scattering the cut instead pickles it on the client, copies it through a socket and unpickles it
on the worker, and waits for the worker's answer before the next tile is sent: on one machine
that keeps the workers waiting for their tiles.

A worker that does not see the file (one that joined from another machine) raises
:class:`CutFileMissing`, and the client sends that tile's cut again through Dask.
"""

from __future__ import annotations

import json
import os

import numpy as np

from .. import _core
from . import _tile_files


class CutFileMissing(Exception):
    """A task's worker found no file for its tile's cut (it runs on another machine)."""


class CutFile:
    """A tile's cut of a partition fit, in the file ``path`` on the client's machine."""

    __slots__ = ("path",)

    def __init__(self, path: str):
        self.path = path

    def __reduce__(self):
        return CutFile, (self.path,)

    def load(self) -> _core.VariationalSurface | _core.BlobField:
        """The cut: the same bits as the field written. Raises :class:`CutFileMissing` when
        this process does not see the file."""
        try:
            with _tile_files.mapped_arrays(self.path) as arrays:
                header = json.loads(arrays[-1].tobytes())
                state = dict(header["entries"], **dict(zip(header["arrays"], arrays)))
                if state.pop(BLOB_FIELD, False):
                    args = [state.pop(k) for k in ("centers", "radii", "strengths", "threshold")]
                    return _core.BlobField(*args, **state)
                return _core.VariationalSurface.from_state(state)
        except FileNotFoundError:
            raise CutFileMissing(self.path) from None


#: The entry that marks a blob field's file (its constructor's arguments, not a state).
BLOB_FIELD = "blob_field"


def write(directory: str, tile: int, field: _core.VariationalSurface | _core.BlobField) -> CutFile | None:
    """Writes ``field`` (a tile's cut) to a file in ``directory``; None when it cannot be
    written (nothing is left behind)."""
    if isinstance(field, _core.BlobField):
        (centers, radii, strengths, threshold), keywords = field.__getnewargs_ex__()
        state = dict(keywords, centers=centers, radii=radii, strengths=strengths, threshold=threshold)
        state[BLOB_FIELD] = True
    else:
        state = field.to_state()
    arrays = {k: v for k, v in state.items() if isinstance(v, np.ndarray)}
    # 8-byte elements first, so that every array's data is aligned in the file.
    names = sorted(arrays, key=lambda k: -arrays[k].dtype.itemsize)
    header = {"arrays": names, "entries": {k: v for k, v in state.items() if k not in arrays}}
    path = os.path.join(directory, f"cut-{tile}")
    try:
        _tile_files.write_arrays(path, [arrays[k] for k in names] + [np.frombuffer(json.dumps(header).encode(), np.uint8)])
    except OSError:
        return None
    return CutFile(path)


def remove(cut: CutFile) -> None:
    """Removes a cut's file (gone already: nothing to do)."""
    try:
        os.remove(cut.path)
    except OSError:
        pass
