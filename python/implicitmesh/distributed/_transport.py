"""How the pieces of a tiled run travel between the client and the workers: the
:class:`Transport` of the tiles' meshes back to the weld, and :class:`SentCuts`, the route of the
fields' cuts to the workers."""

from __future__ import annotations

import os
from concurrent.futures import CancelledError
from dataclasses import dataclass
from typing import Any, Literal

from .. import _core
from . import _cut_files


@dataclass(frozen=True)
class Transport:
    """How each task's tile mesh reaches the weld, one for the run (chosen by the client).

    ``kind``:

    - ``"dask"``: in the task's result, through Dask's comms.
    - ``"files"``: written by the worker into a file in the run's ``directory`` on the client's
      machine (:mod:`._tile_files`) when it takes at least ``min_bytes`` bytes and the worker
      sees the directory; otherwise through Dask.
    - ``"keep"``: left on the worker when it takes at least ``min_bytes`` bytes, for the weld in
      place (:mod:`._weld_in_place`) to have its rows written there; otherwise through Dask.
    - ``"output"``: written to ``directory/tile-i-j-k.npz`` (a run written to a directory).
    """

    kind: Literal["dask", "files", "keep", "output"]
    directory: str | None = None
    min_bytes: int = 0

    @classmethod
    def dask(cls) -> "Transport":
        return cls("dask")

    @classmethod
    def files(cls, directory: str, min_bytes: int) -> "Transport":
        return cls("files", directory, min_bytes)

    @classmethod
    def keep(cls, min_bytes: int) -> "Transport":
        return cls("keep", None, min_bytes)

    @classmethod
    def output(cls, directory: str) -> "Transport":
        return cls("output", directory)


class SentCuts:
    """How the tiles' cuts of a partition fit, and those of a blob field of at least
    ``MIN_SENT_BLOBS`` primitives, reach the workers: through files in the run's ``directory``
    when every worker sees it (:mod:`._cut_files`), else scattered straight to a worker instead
    of travelling inside the task through the scheduler, which a ``LocalCluster`` runs in the
    client's process. A cut's file is removed when its tile is done, unless ``keep_files`` (its
    tile's arrays stay on a worker, which Dask recomputes them on if the worker dies)."""

    #: Smaller blob cuts (under 1.3 MB, 40 bytes per primitive) travel inside their task, without
    #: a file or a round trip to a worker per tile.
    MIN_SENT_BLOBS = 1 << 15

    def __init__(self, client: Any, directory: str | None, keep_files: bool):
        self.client, self.keep_files = client, keep_files
        self.directory = directory if directory is not None and self._workers_see(directory) else None
        self.scattered: dict[int, Any] = {}
        self.files: dict[int, _cut_files.CutFile] = {}

    def _workers_see(self, directory: str) -> bool:
        try:
            seen = self.client.run(os.path.isdir, directory)
        except Exception:  # a worker lost during the call: the cuts go through Dask
            return False
        return bool(seen) and all(seen.values())

    def takes(self, part: Any) -> bool:
        """Whether the cut ``part`` is sent this way."""
        if isinstance(part, _core.BlobField):
            return len(part) >= self.MIN_SENT_BLOBS
        return isinstance(part, _core.VariationalSurface)

    def send(self, part: _core.VariationalSurface | _core.BlobField, i: int) -> Any:
        """What tile ``i``'s task receives for ``part``."""
        if self.directory is not None:
            cut = _cut_files.write(self.directory, i, part)
            if cut is not None:
                self.files[i] = cut
                return cut
        self.scattered[i] = self.client.scatter(part, direct=True, hash=False)
        return self.scattered[i]

    def lost(self, i: int, error: BaseException) -> bool:
        """Whether tile ``i`` failed with ``error`` because its cut did not reach its worker
        (its scattered cut lost with a worker: Dask does not recompute scattered data; or a
        worker that does not see its file): it is then sent again inside its task."""
        if isinstance(error, CancelledError) and self.scattered.pop(i, None) is not None:
            return True
        if isinstance(error, _cut_files.CutFileMissing) and i in self.files:
            _cut_files.remove(self.files.pop(i))
            return True
        return False

    def done(self, i: int) -> None:
        """Tile ``i``'s result has arrived: its cut is no longer needed."""
        self.scattered.pop(i, None)
        if not self.keep_files and i in self.files:
            _cut_files.remove(self.files.pop(i))

    def futures(self) -> list:
        return list(self.scattered.values())
