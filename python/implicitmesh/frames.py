"""Reading particle frames (simulation output) from files: :func:`read_particles`.

Formats, by suffix:

- ``.npy``: an ``(N, 3)`` array, or a structured array with fields ``x``, ``y``, ``z``.
- ``.npz``: the array named ``key``; by default the file's only array, else the first of
  ``positions``, ``points``, ``x`` the file holds. The other arrays of length N are its
  attributes.
- ``.ply``: the ``vertex`` element's ``x``, ``y``, ``z`` (ASCII, binary little- or big-endian);
  the other vertex properties are its attributes.
- ``.vtk``, ``.vtu``, ``.vtp``, ``.xdmf`` and the other formats of meshio: the points, and the
  point data as attributes; VTK's own formats (``.vtk``, ``.vtu``, ``.vtp``, ...) through
  pyvista when it is installed, else meshio (``pip install meshio``); the others through meshio,
  else pyvista. When the first reader fails on a file, the other is tried.

Positions come back as stored (float32 or float64), without a copy where the file's layout
allows one; :class:`~implicitmesh.BlobField` reads either dtype as it is.
"""

from __future__ import annotations

import importlib.util
import os
from typing import Any, Sequence

import numpy as np

__all__ = ["read_particles", "NPZ_KEYS"]

#: The keys :func:`read_particles` looks for, in order, in an ``.npz`` file of several arrays.
NPZ_KEYS = ("positions", "points", "x")

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_MESHIO_SUFFIXES = (".vtk", ".vtu", ".vtp", ".pvtu", ".xdmf", ".xmf", ".h5m", ".med", ".cgns", ".mdpa")


def read_particles(
    path: str | os.PathLike[str],
    *,
    key: str | None = None,
    attributes: Sequence[str] | None = None,
) -> np.ndarray | tuple[np.ndarray, dict[str, np.ndarray]]:
    """Reads the particle positions of one frame.

    Parameters
    ----------
    path : str or path-like
        A ``.npy``, ``.npz``, ``.ply``, or a meshio format (``.vtk``, ``.vtu``, ...) file; see
        the module's documentation for what is read from each.
    key : str, optional
        ``.npz`` only: the array of positions (default: the only array, else the first of
        :data:`NPZ_KEYS`).
    attributes : sequence of str, optional
        Per-particle values to return as well (e.g. ``("radius", "density")``): ``.npz``
        arrays, PLY vertex properties or meshio point data of that name.

    Returns
    -------
    positions : (N, 3) float32 or float64
        As stored (integer positions are converted to float64).
    attributes : dict of str to (N,) or (N, k) arrays
        Only when ``attributes`` is given, one entry per name asked for.

    Raises
    ------
    ValueError
        Naming ``path`` for an unknown suffix or a file without positions (or not ``(N, 3)``),
        ``key`` for a missing ``.npz`` array, ``attributes`` for a missing attribute.
    ImportError
        For a meshio format when neither meshio nor pyvista is installed.
    FileNotFoundError
        When ``path`` does not exist.
    """
    name = os.fspath(path)
    if not os.path.exists(name):
        raise FileNotFoundError(f"path: no such file {name!r}")
    suffix = os.path.splitext(name)[1].lower()
    if key is not None and suffix != ".npz":
        raise ValueError(f"key: only .npz files hold named arrays, got a {suffix or 'suffix-less'} file {name!r}")
    if suffix == ".npy":
        positions, extra = _positions(np.load(name, allow_pickle=False), name), {}
    elif suffix == ".npz":
        positions, extra = _read_npz(name, key)
    elif suffix == ".ply":
        positions, extra = _read_ply(name)
    elif suffix in _MESHIO_SUFFIXES:
        positions, extra = _read_meshio(name)
    else:
        raise ValueError(
            f"path: unknown particle file suffix {suffix!r} of {name!r}; "
            f"read .npy, .npz, .ply, {', '.join(_MESHIO_SUFFIXES)}"
        )
    if attributes is None:
        return positions
    if isinstance(attributes, str):
        attributes = (attributes,)
    missing = [a for a in attributes if a not in extra]
    if missing:
        have = ", ".join(sorted(extra)) or "none"
        raise ValueError(f"attributes: {name!r} has no per-particle {missing[0]!r} (it has: {have})")
    return positions, {a: extra[a] for a in attributes}


def _positions(a: np.ndarray, name: str) -> np.ndarray:
    """``a`` as (N, 3) float32 or float64 positions, a structured array's x, y, z stacked."""
    if a.dtype.names is not None:
        if not all(c in a.dtype.names for c in "xyz"):
            raise ValueError(f"path: {name!r} holds a structured array without fields x, y, z")
        return _stack_xyz(a, name)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"path: {name!r} holds an array of shape {a.shape}, not (N, 3) positions")
    if a.dtype in (np.float32, np.float64):
        return a
    if a.dtype.kind in "iu" or (a.dtype.kind == "f" and a.dtype.itemsize < 8):
        return a.astype(np.float64)
    raise ValueError(f"path: {name!r} holds {a.dtype} positions; expected float32 or float64")


def _stack_xyz(table: Any, name: str) -> np.ndarray:
    """x, y, z columns of a structured array (a view when they are adjacent, of one float dtype
    and the table has no other fields, else a copy)."""
    names = table.dtype.names
    dt = table.dtype.fields["x"][0]
    if names == ("x", "y", "z") and dt in (np.float32, np.float64) and all(
        table.dtype.fields[c][0] == dt for c in "xyz"
    ):
        return _positions(table.view(dt).reshape(-1, 3), name)
    common = np.result_type(*(table.dtype.fields[c][0] for c in "xyz"))
    if common not in (np.float32, np.float64):
        common = np.dtype(np.float64)
    out = np.empty((len(table), 3), dtype=common)
    for k, c in enumerate("xyz"):
        out[:, k] = table[c]
    return out


def _read_npz(name: str, key: str | None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    with np.load(name, allow_pickle=False) as f:
        files = list(f.files)
        if key is None:
            found = files if len(files) == 1 else [k for k in NPZ_KEYS if k in files][:1]
            if not found:
                raise ValueError(
                    f"path: {name!r} holds the arrays {', '.join(files) or 'none'}; none is named "
                    f"{', '.join(NPZ_KEYS)}: pass key="
                )
            key = found[0]
        elif key not in files:
            raise ValueError(f"key: {name!r} has no array {key!r} (it has: {', '.join(files) or 'none'})")
        positions = _positions(f[key], name)
        extra = {k: f[k] for k in files if k != key}
    return positions, {k: v for k, v in extra.items() if v.ndim >= 1 and len(v) == len(positions)}


def _read_ply(name: str) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The vertex element of a PLY file: positions and the other properties."""
    with open(name, "rb") as f:
        if f.readline().strip() != b"ply":
            raise ValueError(f"path: {name!r} is not a PLY file (no 'ply' line first)")
        fmt, elements = None, []  # elements: [name, count, [(property, dtype) or None for lists]]
        while True:
            line = f.readline()
            if not line:
                raise ValueError(f"path: {name!r} has no 'end_header' line")
            words = line.decode("ascii", "replace").split()
            if not words or words[0] in ("comment", "obj_info"):
                continue
            if words[0] == "end_header":
                break
            if words[0] == "format":
                fmt = words[1]
            elif words[0] == "element":
                elements.append([words[1], int(words[2]), []])
            elif words[0] == "property" and elements:
                if words[1] == "list":
                    elements[-1][2].append((words[-1], None))
                elif words[1] in _PLY_TYPES:
                    elements[-1][2].append((words[2], _PLY_TYPES[words[1]]))
                else:
                    raise ValueError(f"path: {name!r} has a property of unknown type {words[1]!r}")
        order = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": None}
        if fmt not in order:
            raise ValueError(f"path: {name!r} has an unknown PLY format {fmt!r}")
        if not elements or elements[0][0] != "vertex":
            # Elements before the vertices would have to be skipped (lists make that costly).
            raise ValueError(f"path: {name!r} has no 'vertex' element first")
        _, count, props = elements[0]
        if any(dt is None for _, dt in props):
            raise ValueError(f"path: {name!r} has list properties on its vertices")
        if not all(c in [p for p, _ in props] for c in "xyz"):
            raise ValueError(f"path: {name!r} has no vertex properties x, y, z")
        if order[fmt] is None:
            rows = np.loadtxt(f, max_rows=count, ndmin=2, dtype=np.float64)
            if rows.shape != (count, len(props)):
                raise ValueError(f"path: {name!r} has {rows.shape[0]} vertex rows of {count}")
            table = np.empty(count, dtype=[(p, dt) for p, dt in props])
            for k, (p, _) in enumerate(props):
                table[p] = rows[:, k]
        else:
            dtype = np.dtype([(p, order[fmt] + dt) for p, dt in props])
            table = np.fromfile(f, dtype=dtype, count=count)
            if len(table) != count:
                raise ValueError(f"path: {name!r} ends after {len(table)} of {count} vertices")
            if order[fmt] == ">":
                table = table.astype(table.dtype.newbyteorder("="))
    positions = _stack_xyz(table, name)
    return positions, {p: table[p] for p, _ in props if p not in "xyz"}


#: Suffixes of VTK's own formats, which pyvista (VTK) reads first.
_VTK_SUFFIXES = (".vtk", ".vtu", ".vtp", ".pvtu")


def _meshio_points(name: str) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    import meshio

    m = meshio.read(name)
    return np.asarray(m.points), dict(m.point_data)


def _pyvista_points(name: str) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    import pyvista

    m = pyvista.read(name)
    return np.asarray(m.points), {k: np.asarray(m.point_data[k]) for k in m.point_data.keys()}


def _read_meshio(name: str) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Points and point data through pyvista or meshio (see the module), the other tried when
    the first is not installed or fails on the file."""
    readers = [("meshio", _meshio_points), ("pyvista", _pyvista_points)]
    if os.path.splitext(name)[1].lower() in _VTK_SUFFIXES:
        readers.reverse()
    installed = [(m, read) for m, read in readers if importlib.util.find_spec(m) is not None]
    if not installed:
        raise ImportError(f"reading {os.path.splitext(name)[1]} particle files needs meshio: pip install meshio")
    failures = []
    for module, read in installed:
        try:
            points, data = read(name)
            break
        # meshio exits (SystemExit) on some files it cannot parse.
        except (Exception, SystemExit) as e:
            failures.append(f"{module}: {type(e).__name__}: {e}")
    else:
        raise ValueError(f"path: cannot read {name!r} ({'; '.join(failures)})")
    if points.ndim != 2 or len(points) == 0:
        raise ValueError(f"path: {name!r} holds no points")
    return _positions(points, name), data
