"""Runs every ``benchmarks/bench_*.py`` one after another and concatenates their markdown sections
into ``BENCHMARKS.md`` at the repository root, under a header with the machine, the date, the
command and the git commit.

    python benchmarks/run_all.py                 # full runs → BENCHMARKS.md
    python benchmarks/run_all.py --quick         # smoke test of every bench (→ BENCHMARKS.md too,
                                                 # marked QUICK; pass --output to keep it elsewhere)
    python benchmarks/run_all.py --only rbf      # a subset, by name (bench_NAME.py)

Each bench script must accept ``--output PATH`` (its section, also printed to stdout) and
``--quick``; its section is also kept in ``benchmarks/results/NAME.md``.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from _timing import cpu_snapshot, foreign_load, loadavg, machine_info, machine_markdown  # noqa: E402


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


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="Run all benchmarks and write BENCHMARKS.md.")
    p.add_argument("--quick", action="store_true", help="pass --quick to every bench (smoke test)")
    p.add_argument("--only", nargs="*", default=None, help="bench names to run (bench_NAME.py), default all; the other sections are "
                        "copied from their last results in benchmarks/results/")
    p.add_argument("--output", default=str(ROOT / "BENCHMARKS.md"), help="combined markdown (default BENCHMARKS.md)")
    p.add_argument("--wait-idle", type=float, default=0.0, metavar="SECONDS",
                   help="before each bench, wait up to SECONDS for other processes to use < 0.3 cores")
    a = p.parse_args(argv)

    every = sorted(HERE.glob("bench_*.py"))
    scripts = every
    if a.only:
        scripts = [s for s in every if s.stem[len("bench_"):] in a.only]
    if not scripts:
        print("no bench_*.py selected", file=sys.stderr)
        return 2
    results = HERE / "results"
    results.mkdir(exist_ok=True)

    started = _dt.datetime.now().astimezone()
    load_before = loadavg()
    snap = cpu_snapshot()
    t0 = time.perf_counter()
    sections, summary, waits = [], [], []
    for script in scripts:
        name = script.stem[len("bench_"):]
        out = results / f"{name}.md"
        cmd = [sys.executable, str(script), "--output", str(out)] + (["--quick"] if a.quick else [])
        if a.wait_idle > 0:
            waits.append(f"`{script.name}`: {wait_idle(a.wait_idle)}")
        print(f"[run_all] {' '.join(cmd)}", file=sys.stderr, flush=True)
        s0 = time.perf_counter()
        proc = subprocess.run(cmd, stdout=subprocess.PIPE, text=True)
        dt = time.perf_counter() - s0
        if proc.returncode != 0:
            sections.append(f"## {name}\n\n**FAILED** (exit code {proc.returncode}) — see the run's stderr.\n")
            summary.append(f"`{script.name}` FAILED after {dt:.0f} s")
        else:
            sections.append(out.read_text() if out.exists() else proc.stdout)
            summary.append(f"`{script.name}` {dt:.0f} s")
    if a.only:
        # Sections not re-run keep their last results (each section states its own run date).
        kept = {}
        for script in every:
            name = script.stem[len("bench_"):]
            old = results / f"{name}.md"
            if script not in scripts and old.exists():
                kept[name] = old.read_text()
                summary.append(f"`{script.name}` not re-run (section from its last run, dated inside)")
        order = [s.stem[len("bench_"):] for s in every]
        ran = {s.stem[len("bench_"):]: sec for s, sec in zip(scripts, sections)}
        sections = [ran[n] if n in ran else kept[n] for n in order if n in ran or n in kept]
    total = time.perf_counter() - t0
    load_after = loadavg()
    other = foreign_load(snap, cpu_snapshot())

    info = machine_info(("numpy", "scipy", "scikit-image", "ferreus_rbf", "implicitmesh"))
    argv = [os.path.relpath(x, ROOT) if x.startswith(str(ROOT) + os.sep) else x for x in sys.argv]
    command = " ".join(["python", *argv])
    header = [
        "# Benchmarks" + (" (QUICK smoke run: not representative)" if a.quick else ""),
        "",
        "Written by `benchmarks/run_all.py`; do not edit by hand. Each section below comes from one "
        "`benchmarks/bench_*.py` and states its own cases, runs and ratios (peer / ours: above 1, ours is faster).",
        "",
        f"- Date: {started:%Y-%m-%d %H:%M %Z}",
        f"- Command: `{command}` (from the repository root)",
        f"- Commit: {git_describe()}",
        machine_markdown(info),
        f"- Load average (1/5/15 min) before → after all runs: {load_before} → {load_after}",
        f"- Other processes during all runs: "
        + ("unknown" if other is None else f"{other:.2f} of {os.cpu_count()} cores on average")
        + " (machine busy time from /proc/stat minus the benchmarks' own CPU time)",
        f"- Sections: {', '.join(summary)}; total {total:.0f} s",
    ]
    if waits:
        header.append(f"- Waiting for an idle machine: {'; '.join(waits)}")
    header.append("")
    text = "\n".join(header) + "\n" + "\n".join(s.rstrip() + "\n" for s in sections)
    Path(a.output).write_text(text)
    sys.stdout.write(text)
    print(f"[run_all] wrote {a.output}", file=sys.stderr)
    return 0 if all("FAILED" not in s for s in summary) else 1


if __name__ == "__main__":
    sys.exit(main())
