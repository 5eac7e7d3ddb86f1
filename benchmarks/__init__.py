"""The benchmarks of implicitmesh against its peers, run from the repository root as modules:

    python -m benchmarks.run_all [--quick] [--only NAME ...]   # every section → BENCHMARKS.md
    python -m benchmarks.run_all --render                      # BENCHMARKS.md from the stored results
    python -m benchmarks.bench_octree [--quick]                # one section

Each ``bench_NAME`` module has ``measure(args) -> dict`` (the raw results: every timing's runs,
exact counts, the machine and the run) and ``render(raw) -> str`` (its markdown section). The
raw results are kept in ``benchmarks/results/NAME.json`` and the section in
``benchmarks/results/NAME.md``. The package is not part of the wheel (``pyproject.toml`` packages
``python/implicitmesh`` alone).

Real fluid frames: ``python -m benchmarks.sph_frames`` simulates SPlisHSPlasH's dam break and caches
its frames (``pip install pysplishsplash``); ``bench_particles --cases dam-break-1e5`` meshes them
(:mod:`benchmarks.frame_cases`) and measures smoothness (:mod:`benchmarks.smoothness`);
``sph_pictures`` draws them for the docs; ``frame_phases`` times our phases on a frame.
"""
