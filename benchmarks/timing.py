"""Helpers shared by the ``benchmarks.bench_*`` modules: timing, machine facts, the record of a
run, markdown tables, running a peer in a subprocess under another BLAS thread setting, and the
command line of a section (measure, store the raw results as JSON, render the markdown from them).

Nothing here imports numpy at module level, so a subprocess can set ``OPENBLAS_NUM_THREADS``
before numpy (and so OpenBLAS) is loaded.
"""

from __future__ import annotations

import argparse
import ctypes
import datetime as _dt
import glob
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

#: The repository root (the parent of the ``benchmarks`` package).
ROOT = Path(__file__).resolve().parent.parent
#: Where the sections keep their raw results (NAME.json) and markdown (NAME.md) by default.
RESULTS = ROOT / "benchmarks" / "results"

__all__ = [
    "ROOT",
    "RESULTS",
    "Timing",
    "timeit_median",
    "cpu_snapshot",
    "foreign_load",
    "loadavg",
    "cpu_model",
    "openblas_threads",
    "machine_info",
    "machine_markdown",
    "md_table",
    "fmt_s",
    "fmt_ratio",
    "fmt_cpu_per_wall",
    "fmt_foreign_load",
    "run_worker",
    "blas_env",
    "command_line",
    "RunRecord",
    "run_markdown",
    "section_parser",
    "results_dir",
    "save_raw",
    "load_raw",
    "record_section",
    "run_section",
]


@dataclass
class Timing:
    """Wall-clock seconds of ``runs`` timed calls (after ``warmup`` untimed ones)."""

    times: list[float]
    warmup: int
    result: Any = field(default=None, repr=False)  # what the last call returned
    cpu_times: list[float] = field(default_factory=list)  # process CPU seconds (all threads) per run
    foreign_load: float | None = None  # cores busy with other processes during the timed runs

    @property
    def median(self) -> float:
        return statistics.median(self.times)

    @property
    def min(self) -> float:
        return min(self.times)

    @property
    def runs(self) -> int:
        return len(self.times)

    @property
    def cpu_per_wall(self) -> float | None:
        """Median over runs of CPU seconds / wall seconds: about the number of busy threads."""
        if not self.cpu_times:
            return None
        return statistics.median(c / w for c, w in zip(self.cpu_times, self.times) if w > 0)

    def to_json(self) -> dict:
        return {
            "times": self.times,
            "cpu_times": self.cpu_times,
            "warmup": self.warmup,
            "median": self.median,
            "runs": self.runs,
            "cpu_per_wall": self.cpu_per_wall,
            "foreign_load": self.foreign_load,
        }

    @classmethod
    def from_json(cls, d: dict) -> "Timing":
        return cls(list(d["times"]), int(d["warmup"]), None, list(d.get("cpu_times", [])), d.get("foreign_load"))


def run_case_process(module: str, args: Sequence[str], case: dict) -> dict:
    """``python -m module one *args`` in a fresh process (its peak memory its own): the JSON
    line it prints, or ``case`` with the last line of its error output under ``"error"``."""
    r = subprocess.run([sys.executable, "-m", module, "one", *args], capture_output=True, text=True, cwd=ROOT)
    if r.returncode != 0:
        if r.returncode < 0:
            import signal

            why = f"the process died of {signal.Signals(-r.returncode).name}"
        else:
            why = f"exit status {r.returncode}"
        return {**case, "error": r.stderr.strip().splitlines()[-1] if r.stderr.strip() else why}
    return json.loads(r.stdout)


def timeit_median(fn: Callable[[], Any], runs: int = 5, warmup: int = 1) -> Timing:
    """Calls ``fn()`` ``warmup`` times untimed, then ``runs`` times timed with
    :func:`time.perf_counter`; returns a :class:`Timing` (``.median``, ``.times``, ``.result``)."""
    if runs < 1:
        raise ValueError("runs must be >= 1")
    result = None
    for _ in range(warmup):
        result = fn()
    times, cpu = [], []
    s0 = cpu_snapshot()
    for _ in range(runs):
        c0 = time.process_time()
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return Timing(times, warmup, result, cpu, foreign_load(s0, cpu_snapshot()))


def cpu_snapshot() -> tuple[float, float, float] | None:
    """(wall, CPU seconds busy on the whole machine, CPU seconds of this process and its waited-for
    children) — for :func:`foreign_load`. None where /proc/stat is missing."""
    try:
        with open("/proc/stat") as f:
            fields = [int(x) for x in f.readline().split()[1:]]
    except (OSError, ValueError):
        return None
    tick = os.sysconf("SC_CLK_TCK")
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)  # idle + iowait
    busy = (sum(fields[:8]) - idle) / tick  # user nice system idle iowait irq softirq steal
    t = os.times()
    own = t.user + t.system + t.children_user + t.children_system
    return time.monotonic(), busy, own


def foreign_load(a, b) -> float | None:
    """Average number of cores other processes kept busy between two :func:`cpu_snapshot` calls
    (machine-wide busy CPU time minus our own, over the wall time; ±0.1 from tick granularity)."""
    if a is None or b is None or b[0] - a[0] <= 0:
        return None
    return max(0.0, ((b[1] - a[1]) - (b[2] - a[2])) / (b[0] - a[0]))


def loadavg() -> tuple[float, float, float]:
    """The 1, 5 and 15 minute load averages from /proc/loadavg."""
    try:
        with open("/proc/loadavg") as f:
            a, b, c = f.read().split()[:3]
        return float(a), float(b), float(c)
    except OSError:
        return os.getloadavg()


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def vector_instructions() -> str:
    """The vector instruction sets of this CPU that implicitmesh's kernels use ("AVX-512",
    "AVX2 and FMA", or "no AVX2"), from /proc/cpuinfo ("unknown" elsewhere)."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("flags"):
                    flags = set(line.split(":", 1)[1].split())
                    if {"avx512f", "avx2", "fma"} <= flags:
                        return "AVX-512"
                    if {"avx2", "fma"} <= flags:
                        return "AVX2 and FMA, no AVX-512"
                    return "no AVX2"
    except OSError:
        pass
    return "unknown"


def openblas_threads() -> dict[str, int]:
    """Threads the OpenBLAS libraries bundled with numpy and scipy will use (read with ctypes, as
    threadpoolctl would; {} when the libraries are not found). Loads numpy."""
    import numpy

    site = os.path.dirname(os.path.dirname(numpy.__file__))
    out: dict[str, int] = {}
    for label, pattern in (("numpy", "numpy.libs/lib*openblas*.so*"), ("scipy", "scipy.libs/lib*openblas*.so*")):
        for path in glob.glob(os.path.join(site, pattern)):
            try:
                lib = ctypes.CDLL(path)
            except OSError:
                continue
            for sym in (
                "scipy_openblas_get_num_threads64_",
                "scipy_openblas_get_num_threads",
                "openblas_get_num_threads64_",
                "openblas_get_num_threads",
            ):
                if hasattr(lib, sym):
                    out[label] = int(getattr(lib, sym)())
                    break
    return out


def _version(module: str) -> str:
    try:
        from importlib.metadata import version

        return version(module)
    except Exception:  # noqa: BLE001
        return "not installed"


def machine_info(packages: Sequence[str] = ("numpy", "scipy")) -> dict[str, Any]:
    """Facts about this machine and the Python stack, for a benchmark's header."""
    info: dict[str, Any] = {
        "cpu": cpu_model(),
        "vector": vector_instructions(),
        "cores": os.cpu_count(),
        "affinity": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "python": platform.python_version(),
        "platform": platform.platform(),
        "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "unset (OpenBLAS default)"),
        "loadavg": loadavg(),
    }
    for p in packages:
        info[p] = _version(p)
    try:
        with open("/proc/meminfo") as f:
            kb = int(f.readline().split()[1])
        info["memory_gib"] = round(kb / 2**20, 1)
    except (OSError, ValueError, IndexError):
        pass
    return info


def machine_markdown(info: dict[str, Any], extra: dict[str, str] | None = None) -> str:
    """A bullet list of :func:`machine_info` (plus ``extra`` lines)."""
    lines = [
        f"- CPU: {info['cpu']}" + (f" ({info['vector']})" if "vector" in info else "")
        + f", {info['cores']} logical cores"
        + (f" ({info['affinity']} usable)" if info.get("affinity") not in (None, info["cores"]) else "")
        + (f", {info['memory_gib']} GiB RAM" if "memory_gib" in info else ""),
        f"- Python {info['python']} on {info['platform']}",
    ]
    skip = {"cpu", "vector", "cores", "affinity", "python", "platform", "OPENBLAS_NUM_THREADS", "loadavg", "memory_gib"}
    versions = ", ".join(f"{k} {v}" for k, v in info.items() if k not in skip)
    if versions:
        lines.append(f"- {versions}")
    lines.append(f"- OPENBLAS_NUM_THREADS in the main process: {info['OPENBLAS_NUM_THREADS']}")
    for k, v in (extra or {}).items():
        lines.append(f"- {k}: {v}")
    return "\n".join(lines)


def md_table(headers: Sequence[str], rows: Sequence[Sequence[Any]], align: str | None = None) -> str:
    """A GitHub markdown table; ``align`` is one letter per column (l, r, c)."""
    align = align or "l" + "r" * (len(headers) - 1)
    sep = {"l": "---", "r": "---:", "c": ":---:"}
    out = ["| " + " | ".join(map(str, headers)) + " |", "|" + "|".join(sep[a] for a in align) + "|"]
    for r in rows:
        out.append("| " + " | ".join("" if c is None else str(c) for c in r) + " |")
    return "\n".join(out)


def fmt_s(seconds: float | None) -> str:
    if seconds is None:
        return "—"
    if seconds >= 100:
        return f"{seconds:.0f}"
    if seconds >= 10:
        return f"{seconds:.1f}"
    if seconds >= 1:
        return f"{seconds:.2f}"
    if seconds >= 0.01:
        return f"{seconds:.3f}"
    return f"{seconds:.4f}"


def fmt_ratio(peer: float | None, ours: float | None) -> str:
    if not peer or not ours:
        return "—"
    r = peer / ours
    return f"{r:.2f}×" if r < 10 else f"{r:.1f}×" if r < 100 else f"{r:.0f}×"


def blas_env(threads: int | None) -> dict[str, str]:
    """A copy of os.environ with ``OPENBLAS_NUM_THREADS`` set to ``threads``, or removed when
    ``threads`` is None (OpenBLAS then uses its default: one thread per core)."""
    env = dict(os.environ)
    if threads is None:
        env.pop("OPENBLAS_NUM_THREADS", None)
    else:
        env["OPENBLAS_NUM_THREADS"] = str(threads)
    return env


def run_worker(module: str, args: Sequence[str], threads: int | None, timeout: float | None = None) -> dict:
    """Runs ``python -m module *args --json-out FILE`` from the repository root in a subprocess with
    the given OpenBLAS thread setting and returns the JSON it wrote. The worker's stderr passes
    through (progress)."""
    with tempfile.TemporaryDirectory(prefix="bench_") as tmp:
        out = os.path.join(tmp, "result.json")
        cmd = [sys.executable, "-m", module, *args, "--json-out", out]
        subprocess.run(cmd, env=blas_env(threads), check=True, timeout=timeout, stdout=sys.stderr, cwd=ROOT)
        with open(out) as f:
            return json.load(f)


def fmt_cpu_per_wall(t: Timing | None) -> str:
    """A table cell: the timing's CPU seconds per wall second, one decimal."""
    c = None if t is None else t.cpu_per_wall
    return "—" if c is None else f"{c:.1f}"


def fmt_foreign_load(t: Timing | None) -> str:
    """A table cell: the cores other processes kept busy during the timing, one decimal."""
    return "—" if t is None or t.foreign_load is None else f"{t.foreign_load:.1f}"


def command_line(module: str) -> str:
    """This process's command as ``python -m module ARGS``, with paths under the repository root
    made relative to it and without ``--results DIR`` (where the results go, not what they are)."""
    args: list[str] = []
    skip = False
    for x in sys.argv[1:]:
        if skip or x.startswith("--results="):
            skip = False
            continue
        if x == "--results":
            skip = True
            continue
        args.append(os.path.relpath(x, ROOT) if x.startswith(str(ROOT) + os.sep) else x)
    return " ".join(["python", "-m", module, *args])


class RunRecord:
    """The facts every section states about its run: start date, command, quick flag, machine,
    load averages and the other processes' CPU use. Created when the run starts; :meth:`finish`
    returns them as a JSON-serialisable dict."""

    def __init__(self, module: str, quick: bool):
        self.command = command_line(module)
        self.quick = bool(quick)
        self.started = _dt.datetime.now().astimezone()
        self.load_before = loadavg()
        self.snapshot = cpu_snapshot()

    def finish(self, packages: Sequence[str]) -> dict[str, Any]:
        info = machine_info(packages)
        foreign = foreign_load(self.snapshot, cpu_snapshot())
        return {
            "date": f"{self.started:%Y-%m-%d %H:%M %Z}",
            "timestamp": self.started.isoformat(),
            "command": self.command,
            "quick": self.quick,
            "machine": info,
            "loadavg_before": list(self.load_before),
            "loadavg_after": list(loadavg()),
            "foreign_load": foreign,
        }


def run_markdown(run: dict[str, Any]) -> str:
    """The machine bullet list of a :class:`RunRecord` and its load line."""
    foreign = run["foreign_load"]
    return "\n".join([
        machine_markdown(run["machine"]),
        f"- load average before → after: {tuple(run['loadavg_before'])} → {tuple(run['loadavg_after'])}; "
        f"other processes used {foreign if foreign is None else round(foreign, 2)} cores on average during the run",
    ])


def section_parser(description: str, quick_help: str | None = None) -> argparse.ArgumentParser:
    """The command line of a ``benchmarks.bench_NAME`` module: ``--quick`` and ``--results DIR``."""
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--quick", action="store_true", help=quick_help or "smoke test: fewer cases and runs")
    p.add_argument("--results", default=None, metavar="DIR",
                   help="where NAME.json (raw results) and NAME.md go (default benchmarks/results; "
                        "with --quick a new temporary directory)")
    return p


def results_dir(results: str | None, quick: bool) -> Path:
    """``results`` as an absolute path; by default ``benchmarks/results``, or a new temporary
    directory for a quick run (quick results never replace the stored ones by accident)."""
    if results:
        path = Path(results).resolve()
    elif quick:
        path = Path(tempfile.mkdtemp(prefix="benchmarks_quick_"))
    else:
        path = RESULTS
    path.mkdir(parents=True, exist_ok=True)
    return path


def save_raw(results: Path, name: str, raw: dict[str, Any]) -> Path:
    """Writes ``raw`` to ``results/NAME.json``."""
    path = results / f"{name}.json"
    path.write_text(json.dumps(raw, indent=1, ensure_ascii=False) + "\n")
    return path


def load_raw(results: Path, name: str) -> dict[str, Any] | None:
    """The raw results in ``results/NAME.json``, or None when there are none."""
    path = results / f"{name}.json"
    return json.loads(path.read_text()) if path.exists() else None


def record_section(name: str, measure: Callable[[Any], dict], render: Callable[[dict], str], args: Any) -> int:
    """Runs ``measure(args)``, writes the raw results to ``RESULTS/NAME.json``, renders the markdown
    from that file into ``RESULTS/NAME.md`` and prints it."""
    results = results_dir(args.results, args.quick)
    save_raw(results, name, measure(args))
    md = render(load_raw(results, name))
    (results / f"{name}.md").write_text(md)
    sys.stdout.write(md)
    print(f"[{name}] wrote {results / name}.json and .md", file=sys.stderr, flush=True)
    return 0


def run_section(name: str, measure: Callable[[Any], dict], render: Callable[[dict], str], description: str,
                quick_help: str | None = None) -> int:
    """The ``main`` of a ``benchmarks.bench_NAME`` module without options of its own."""
    return record_section(name, measure, render, section_parser(description, quick_help).parse_args())
