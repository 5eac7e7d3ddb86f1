"""Runs every section's benchmark (``benchmarks.bench_NAME``) one after another, each in its own
process, and writes ``BENCHMARKS.md`` at the repository root: a header with the machine, the
date, the command and the git commit, then the sections rendered from their raw results.

    python -m benchmarks.run_all                  # full runs → benchmarks/results/, BENCHMARKS.md
    python -m benchmarks.run_all --quick          # smoke test of every section → a temporary
                                                  # directory (named on stderr), marked QUICK
    python -m benchmarks.run_all --only rbf       # a subset, by name; the others keep their last results
    python -m benchmarks.run_all --render         # BENCHMARKS.md again from the stored results, no runs

Each section keeps its raw results in ``RESULTS/NAME.json`` and its markdown in ``RESULTS/NAME.md``
(``--results RESULTS``, default ``benchmarks/results``); this run's header facts go to
``RESULTS/run_all.json``. ``--render`` renders each section from its JSON, or keeps its
``NAME.md`` when no JSON is stored (the header says which).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import importlib
import subprocess
import sys
import time
from pathlib import Path

from benchmarks.timing import (
    RESULTS,
    ROOT,
    RunRecord,
    command_line,
    cpu_snapshot,
    foreign_load,
    load_raw,
    machine_markdown,
    results_dir,
    save_raw,
)

#: The sections of BENCHMARKS.md, in order: ``benchmarks.bench_NAME`` modules with
#: ``measure(args) -> dict`` and ``render(raw) -> str``.
SECTIONS = ("blobs", "distributed", "normals", "octree", "particles", "partition", "rbf", "scale", "scans", "subdivision")
#: The packages whose versions the header names.
PACKAGES = ("numpy", "scipy", "scikit-image", "ferreus_rbf", "pysplashsurf", "distributed", "implicitmesh")


def wait_idle(max_seconds: float, threshold: float = 0.3, window: float = 20.0) -> str:
    """Waits (up to ``max_seconds``) until other processes have used under ``threshold`` cores over
    ``window`` seconds; returns what happened, for the header."""
    t0 = time.monotonic()
    while True:
        a = cpu_snapshot()
        time.sleep(window)
        load = foreign_load(a, cpu_snapshot())
        waited = time.monotonic() - t0
        if load is None or load < threshold:
            return f"machine idle (other processes {load if load is None else round(load, 2)} cores) after {waited:.0f} s"
        if waited >= max_seconds:
            return f"gave up waiting for an idle machine after {waited:.0f} s (other processes {load:.2f} cores)"
        print(f"[run_all] other processes use {load:.2f} cores; waiting", file=sys.stderr, flush=True)


def git_describe() -> str:
    try:
        sha = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                             check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT,
                               capture_output=True, text=True, check=True).stdout.strip()
        return sha + (" (with uncommitted changes)" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def relative(path: Path) -> str:
    """``path`` relative to the repository root when it lies under it."""
    try:
        return str(path.relative_to(ROOT))
    except ValueError:
        return str(path)


def stored_section(results: Path, name: str) -> tuple[str | None, str]:
    """The markdown of section ``name`` from ``results`` and where it came from: rendered from
    ``NAME.json`` (and written to ``NAME.md`` again), else ``NAME.md`` as stored, else None."""
    raw = load_raw(results, name)
    if raw is not None:
        md = importlib.import_module(f"benchmarks.bench_{name}").render(raw)
        (results / f"{name}.md").write_text(md)
        return md, f"rendered from {relative(results / name)}.json"
    md_path = results / f"{name}.md"
    if md_path.exists():
        return md_path.read_text(), f"kept from {relative(md_path)} (no raw results stored)"
    return None, "no results stored"


def run_section(name: str, quick: bool, results: Path) -> tuple[str, str]:
    """Runs ``python -m benchmarks.bench_NAME`` in a subprocess; (its section, its summary)."""
    cmd = [sys.executable, "-m", f"benchmarks.bench_{name}"] + (["--quick"] if quick else [])
    if results != RESULTS:
        cmd += ["--results", str(results)]
    print(f"[run_all] {' '.join(cmd)}", file=sys.stderr, flush=True)
    s0 = time.perf_counter()
    proc = subprocess.run(cmd, stdout=subprocess.DEVNULL, cwd=ROOT)
    dt = time.perf_counter() - s0
    md, _ = stored_section(results, name) if proc.returncode == 0 else (None, "")
    if md is None:
        return (f"## {name}\n\n**FAILED** (exit code {proc.returncode}) — see the run's stderr.\n",
                f"`{name}` FAILED after {dt:.0f} s")
    return md, f"`{name}` {dt:.0f} s"


def header(record: dict | None, rendered: dict | None = None) -> str:
    """The head of BENCHMARKS.md: the facts of the run in ``record`` (``run_all.json``), and for
    ``--render`` (``rendered``: its date and command and where each section came from) a line
    saying so."""
    quick = bool(record and record["quick"]) or bool(rendered and rendered["quick"])
    lines = [
        "# Benchmarks" + (" (QUICK smoke run: not representative)" if quick else ""),
        "",
        "Written by `python -m benchmarks.run_all`; do not edit by hand. Each section below comes from one "
        "`benchmarks/bench_*.py` module (`python -m benchmarks.bench_NAME`) and states its own cases, runs and "
        "ratios (peer / ours: above 1, ours is faster). Each section's raw results are kept in "
        "`benchmarks/results/NAME.json`; `python -m benchmarks.run_all --render` writes this file again from them.",
        "",
    ]
    if record is not None:
        other = record["foreign_load"]
        lines += [
            f"- Date: {record['date']}",
            f"- Command: `{record['command']}` (from the repository root)",
            f"- Commit: {record['commit']}",
            machine_markdown(record["machine"]),
            f"- Load average (1/5/15 min) before → after all runs: {tuple(record['loadavg_before'])} → "
            f"{tuple(record['loadavg_after'])}",
            "- Other processes during all runs: "
            + ("unknown" if other is None else f"{other:.2f} of {record['machine']['cores']} cores on average")
            + " (machine busy time from /proc/stat minus the benchmarks' own CPU time)",
            f"- Sections: {', '.join(record['summary'])}; total {record['total']:.0f} s",
        ]
        if record["waits"]:
            lines.append(f"- Waiting for an idle machine: {'; '.join(record['waits'])}")
    if rendered is not None:
        lines.append(
            f"- Rendered {rendered['date']} with `{rendered['command']}` from the stored results, nothing re-run"
            + ("" if record is not None else
               " (no record of the last run of every section is stored: each section states its own run)")
            + ": " + "; ".join(f"`{k}` {v}" for k, v in rendered["sources"].items())
        )
    lines.append("")
    return "\n".join(lines)


def render_stored(results: Path) -> tuple[str, list[str]]:
    """BENCHMARKS.md from the stored results alone, and the names of the sections it holds."""
    record = load_raw(results, "run_all")
    sections, sources, names = [], {}, []
    for name in SECTIONS:
        md, sources[name] = stored_section(results, name)
        if md is not None:
            sections.append(md)
            names.append(name)
    quick = any((load_raw(results, n) or {}).get("run", {}).get("quick", False) for n in names)
    rendered = {"date": f"{_dt.datetime.now().astimezone():%Y-%m-%d %H:%M %Z}",
                "command": command_line("benchmarks.run_all"), "quick": quick, "sources": sources}
    return header(record, rendered) + "\n" + "\n".join(s.rstrip() + "\n" for s in sections), names


def run_sections(a: argparse.Namespace, results: Path) -> tuple[str, bool]:
    """Runs the selected sections; (BENCHMARKS.md, whether all of them ran to the end)."""
    selected = [n for n in SECTIONS if not a.only or n in a.only]
    run = RunRecord("benchmarks.run_all", a.quick)
    t0 = time.perf_counter()
    sections, summary, waits = {}, [], []
    for name in selected:
        if a.wait_idle > 0:
            waits.append(f"`{name}`: {wait_idle(a.wait_idle)}")
        sections[name], line = run_section(name, a.quick, results)
        summary.append(line)
    for name in SECTIONS:
        if name not in selected:
            md, source = stored_section(results, name)
            if md is not None:
                # Sections not re-run keep their last results (each section states its own run date).
                sections[name] = md
                summary.append(f"`{name}` not re-run (section {source}, dated inside)")
    record = {**run.finish(PACKAGES), "commit": git_describe(), "summary": summary,
              "total": time.perf_counter() - t0, "waits": waits}
    save_raw(results, "run_all", record)
    text = header(record) + "\n" + "\n".join(sections[n].rstrip() + "\n" for n in SECTIONS if n in sections)
    return text, all("FAILED" not in s for s in summary)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="Run all benchmarks and write BENCHMARKS.md.")
    p.add_argument("--quick", action="store_true", help="pass --quick to every section (smoke test)")
    p.add_argument("--only", nargs="*", default=None, choices=SECTIONS, metavar="NAME",
                   help=f"sections to run ({', '.join(SECTIONS)}), default all; the others keep their last "
                        "results in the results directory")
    p.add_argument("--render", action="store_true",
                   help="run nothing: write BENCHMARKS.md again from the stored results")
    p.add_argument("--results", default=None, metavar="DIR",
                   help="raw results (NAME.json) and sections (NAME.md) (default benchmarks/results; with "
                        "--quick a new temporary directory)")
    p.add_argument("--output", default=None,
                   help="combined markdown (default BENCHMARKS.md, or DIR/BENCHMARKS.md for another results directory)")
    p.add_argument("--wait-idle", type=float, default=0.0, metavar="SECONDS",
                   help="before each section, wait up to SECONDS for other processes to use < 0.3 cores")
    a = p.parse_args(argv)

    results = results_dir(a.results, a.quick and not a.render)
    output = Path(a.output) if a.output else ROOT / "BENCHMARKS.md" if results == RESULTS else results / "BENCHMARKS.md"
    print(f"[run_all] results in {results}", file=sys.stderr, flush=True)
    if a.render:
        text, names = render_stored(results)
        ok = bool(names)
    else:
        text, ok = run_sections(a, results)
    output.write_text(text)
    sys.stdout.write(text)
    print(f"[run_all] wrote {output}", file=sys.stderr)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
