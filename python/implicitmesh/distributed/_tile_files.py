"""A gathered run's tiles passed through files on the client's machine instead of Dask's comms.

A task whose worker runs on the client's machine (it sees the run's directory, made by the client
in shared memory, ``/dev/shm``, where there is one) writes its tile's arrays into one file there
and returns only the file's name; the client maps the file (the pages the worker wrote, not a
copy), welds the tile from it and deletes it. Dask's comms would copy the tile through a socket
into fresh memory the client must first touch, which on one machine costs more than the tile's
polygonization. A worker that does not see the directory (another machine), or cannot write the
file (shared memory full), returns the arrays as usual.

The file holds the arrays in ``.npy`` format one after another, the 8-byte ones first so that
every array's data is aligned (:func:`write_arrays`, :func:`mapped_arrays`; the order is
``TileMesh.FILE_ORDER``; a partition fit's tile cuts travel the same way to the workers, see
:mod:`._cut_files`).
"""

from __future__ import annotations

import mmap
import os
import shutil
import tempfile
from contextlib import contextmanager
from typing import Iterator

import numpy as np

#: Tiles of fewer bytes go through Dask's comms (a file costs more than sending them).
MIN_BYTES = 1 << 20

#: Where the run's directory goes when the machine has shared memory.
SHARED_MEMORY = "/dev/shm"


#: The run directories' names: this prefix, the client's process id, a dash.
PREFIX = "implicitmesh-tiles-"


def make_directory() -> str | None:
    """A new directory for one run's tile files (in shared memory where there is one), or None
    when none can be made. Directories that clients no longer running left behind (a client
    killed during a run) are removed first."""
    base = SHARED_MEMORY if os.access(SHARED_MEMORY, os.W_OK) else tempfile.gettempdir()
    remove_orphans(base)
    try:
        return tempfile.mkdtemp(prefix=f"{PREFIX}{os.getpid()}-", dir=base)
    except OSError:
        return None


def remove_orphans(base: str) -> None:
    """Removes the run directories in ``base`` whose client process has ended."""
    try:
        names = os.listdir(base)
    except OSError:
        return
    for name in names:
        pid = name[len(PREFIX):].split("-", 1)[0]
        if not (name.startswith(PREFIX) and pid.isdigit()):
            continue
        try:
            os.kill(int(pid), 0)
        except ProcessLookupError:
            remove_directory(os.path.join(base, name))
        except OSError:  # alive, another user's
            pass


def remove_directory(directory: str | None) -> None:
    """Removes a run's directory and the tile files left in it."""
    if directory is not None:
        shutil.rmtree(directory, ignore_errors=True)


def write(directory: str, name: str, arrays: list[np.ndarray]) -> bool:
    """Writes a tile's ``arrays`` to ``directory/name``; False when the directory is not on this
    machine or the file cannot be written (nothing is left behind)."""
    if not os.path.isdir(directory):
        return False
    try:
        write_arrays(os.path.join(directory, name), arrays)
    except OSError:
        return False
    return True


def write_arrays(path: str, arrays: list[np.ndarray]) -> None:
    """Writes ``arrays`` to the file ``path`` in ``.npy`` format one after another (through
    ``path.part``, renamed when complete: the file is whole or absent); each array's data is
    aligned in the file when those before it hold whole multiples of 8 bytes. Raises OSError
    when it cannot be written (nothing is left behind)."""
    tmp = path + ".part"
    try:
        with open(tmp, "wb") as fh:
            for a in arrays:
                np.lib.format.write_array(fh, np.ascontiguousarray(a), allow_pickle=False)
        os.replace(tmp, path)
    except OSError:
        try:
            os.remove(tmp)
        except OSError:
            pass
        raise


@contextmanager
def read(directory: str, name: str) -> Iterator[list[np.ndarray]]:
    """The tile arrays of ``directory/name``, in the order written, read-only views of the file
    mapped in memory, valid inside the ``with`` block; the file is deleted afterwards."""
    path = os.path.join(directory, name)
    try:
        with mapped_arrays(path) as arrays:
            yield arrays
    finally:
        os.remove(path)


@contextmanager
def mapped_arrays(path: str) -> Iterator[list[np.ndarray]]:
    """The arrays :func:`write_arrays` wrote to ``path``, read-only views of the file mapped in
    memory, valid inside the ``with`` block. Raises FileNotFoundError when there is no such
    file."""
    with open(path, "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        populate = getattr(mmap, "MAP_POPULATE", 0)
        mapped = mmap.mmap(fh.fileno(), size, flags=mmap.MAP_SHARED | populate, prot=mmap.PROT_READ) if size else None
        arrays = []
        while fh.tell() < size:
            version = np.lib.format.read_magic(fh)
            header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            shape, fortran, dtype = header(fh)
            count = int(np.prod(shape, dtype=np.int64))
            start = fh.tell()
            data = np.frombuffer(mapped, dtype=dtype, count=count, offset=start) if count else np.empty(0, dtype)
            arrays.append(data.reshape(shape, order="F" if fortran else "C"))
            fh.seek(start + count * dtype.itemsize)
    try:
        yield arrays
    finally:
        arrays.clear()
        data = None
        if mapped is not None:
            try:
                mapped.close()
            except BufferError:  # a caller kept a view: the mapping goes with it
                pass
