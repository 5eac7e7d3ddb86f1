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

from _timing import loadavg, machine_info, machine_markdown  # noqa: E402


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
    p.add_argument("--only", nargs="*", default=None, help="bench names to run (bench_NAME.py), default all")
    p.add_argument("--output", default=str(ROOT / "BENCHMARKS.md"), help="combined markdown (default BENCHMARKS.md)")
    a = p.parse_args(argv)

    scripts = sorted(HERE.glob("bench_*.py"))
    if a.only:
        scripts = [s for s in scripts if s.stem[len("bench_"):] in a.only]
    if not scripts:
        print("no bench_*.py selected", file=sys.stderr)
        return 2
    results = HERE / "results"
    results.mkdir(exist_ok=True)

    started = _dt.datetime.now().astimezone()
    load_before = loadavg()
    t0 = time.perf_counter()
    sections, summary = [], []
    for script in scripts:
        name = script.stem[len("bench_"):]
        out = results / f"{name}.md"
        cmd = [sys.executable, str(script), "--output", str(out)] + (["--quick"] if a.quick else [])
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
    total = time.perf_counter() - t0
    load_after = loadavg()

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
        f"- Sections: {', '.join(summary)}; total {total:.0f} s",
        "",
    ]
    text = "\n".join(header) + "\n" + "\n".join(s.rstrip() + "\n" for s in sections)
    Path(a.output).write_text(text)
    sys.stdout.write(text)
    print(f"[run_all] wrote {a.output}", file=sys.stderr)
    return 0 if all("FAILED" not in s for s in summary) else 1


if __name__ == "__main__":
    sys.exit(main())
