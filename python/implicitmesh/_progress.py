"""Progress reports for long calls: ``progress=True`` shows a tqdm bar when tqdm is installed,
else one line on standard error rewritten in place; a callable gets the count itself."""

from __future__ import annotations

import sys
import time
from typing import Any, Callable


class Progress:
    """A reporter for one call: call it with the count of work done so far (in ``unit``: field
    evaluations, or vertices for subdivision), then :meth:`close` it. ``total`` (optional) is the
    count expected at the end."""

    def __init__(self, what: str, total: int | None = None, unit: str = "evaluations") -> None:
        self.what, self.total, self.unit, self.start = what, total, unit, time.perf_counter()
        try:
            from tqdm.auto import tqdm
        except ImportError:
            self.bar = None
        else:
            self.bar = tqdm(total=total, desc=what, unit=" " + unit, unit_scale=True, leave=False)
        self.done = 0

    def __call__(self, done: int) -> None:
        if self.bar is not None:
            self.bar.update(done - self.done)
        else:
            seconds = time.perf_counter() - self.start
            of = f" of {self.total:,}" if self.total else ""
            print(f"\r{self.what}: {done:,}{of} {self.unit}, {seconds:.1f} s", end="", file=sys.stderr, flush=True)
        self.done = done

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
        else:
            print(file=sys.stderr, flush=True)


def reporter(
    progress: Any, what: str, total: int | None = None, unit: str = "evaluations"
) -> tuple[Callable[[int], None] | None, Callable[[], None]]:
    """The callback to hand the core and a function that ends the report, for ``progress`` as
    users pass it: False/None (nothing), True (a bar or a line), or a callable taking the count."""
    if progress is None or progress is False:
        return None, lambda: None
    if progress is True:
        p = Progress(what, total, unit)
        return p, p.close
    if callable(progress):
        return progress, lambda: None
    raise ValueError(f"progress: expected True, False or a callable taking the count of {unit}, got {progress!r}")
