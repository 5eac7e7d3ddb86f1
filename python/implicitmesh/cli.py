"""Command line: ``implicitmesh demo``, ``implicitmesh reconstruct IN -o OUT`` and
``implicitmesh particles FRAME -o OUT --radius R``."""

from __future__ import annotations

import argparse
import math
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from . import VariationalSurface, __version__, polygonize

__all__ = ["main"]

#: The polygonizers offered for a fitted surface (``"sparse"`` takes blob fields only).
FIT_METHODS = ("octree", "dense", "tracking")

#: Mesh suffixes the output may have (the formats trimesh writes meshes in).
MESH_SUFFIXES = (".ply", ".obj", ".stl", ".off", ".glb", ".gltf", ".3mf", ".dae")



class UsageError(ValueError):
    """A refused argument, found before any work: one line, naming the option."""


class _Parser(argparse.ArgumentParser):
    """An argument parser whose refusals are one line (``implicitmesh: error: ...``, exit 2),
    with the usage left to ``--help``."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


@contextmanager
def step(message: str):
    """Shows ``message`` with a spinner on a terminal while the block runs (the Rust core releases
    the GIL, so the spinner keeps turning), then the seconds it took."""
    tty = sys.stderr.isatty()
    done = threading.Event()
    t0 = time.perf_counter()

    def spin():
        frames = "|/-\\"
        i = 0
        while not done.wait(0.1):
            sys.stderr.write(f"\r{message} {frames[i % 4]} {time.perf_counter() - t0:5.1f} s")
            sys.stderr.flush()
            i += 1

    thread = threading.Thread(target=spin, daemon=True) if tty else None
    if thread:
        thread.start()
    else:
        sys.stderr.write(f"{message} ...\n")
    try:
        yield
    finally:
        done.set()
        if thread:
            thread.join()
        if tty:
            sys.stderr.write(f"\r{message} done in {time.perf_counter() - t0:.2f} s\n")
        sys.stderr.flush()


def _read_input(path: Path):
    """Returns ("mesh", vertices, faces) or ("points", points, normals or None)."""
    suffix = path.suffix.lower()
    if suffix in (".npz",):
        data = np.load(path)
        return "points", data["points"], data["normals"] if "normals" in data else None
    if suffix in (".xyz", ".txt", ".csv", ".pts"):
        arr = np.loadtxt(path, delimiter="," if suffix == ".csv" else None, ndmin=2)
        if arr.shape[1] not in (3,) and arr.shape[1] < 6:
            raise ValueError(f"{path}: expected 3 columns x y z or 6 columns x y z nx ny nz, got shape {arr.shape}")
        return "points", arr[:, :3], arr[:, 3:6] if arr.shape[1] >= 6 else None
    import trimesh

    loaded = trimesh.load(str(path), process=False)
    if isinstance(loaded, trimesh.Scene):
        loaded = loaded.to_mesh() if hasattr(loaded, "to_mesh") else loaded.dump(concatenate=True)
    if isinstance(loaded, trimesh.Trimesh) and len(loaded.faces):
        return "mesh", np.asarray(loaded.vertices), np.asarray(loaded.faces)
    if isinstance(loaded, trimesh.PointCloud):
        raw = loaded.metadata.get("_ply_raw", {}).get("vertex", {}).get("data")
        # Binary PLY gives a structured array, ASCII PLY a dict of columns.
        names = raw.dtype.names if hasattr(raw, "dtype") else (list(raw) if isinstance(raw, dict) else [])
        if raw is not None and names and all(k in names for k in ("nx", "ny", "nz")):
            normals = np.stack([np.asarray(raw[k]).ravel() for k in ("nx", "ny", "nz")], axis=1).astype(np.float64)
            return "points", np.asarray(loaded.vertices), normals
        return "points", np.asarray(loaded.vertices, dtype=np.float64), None
    raise ValueError(f"{path}: neither a triangle mesh nor a point set")


def _check_positive(option: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0):
        raise UsageError(f"{option}: must be a positive number, got {value}")


def _check_resolution(resolution: int) -> None:
    """Refuses a ``--resolution`` the lattice refuses (not positive, or more cells per axis than
    the core takes), before any work; a cube is the largest lattice of a resolution."""
    from . import _core

    try:
        _core.lattice([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], resolution)
    except ValueError as e:
        raise UsageError("--" + str(e)) from None


def _check_output_file(output: str) -> None:
    """Refuses an output mesh whose format trimesh does not write, or whose folder is missing."""
    path = Path(output)
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise UsageError(f"--output: cannot write a {path.suffix or 'suffix-less'} mesh; use one of {', '.join(MESH_SUFFIXES)}")
    if not path.parent.is_dir():
        raise UsageError(f"--output: the folder {str(path.parent)!r} does not exist")


def _check_input_file(path: str) -> None:
    if not Path(path).is_file():
        raise UsageError(f"input: no such file {path!r}")


def _check(args) -> None:
    """Every argument of the command, checked before anything is read or fitted."""
    if args.command in ("demo", "reconstruct"):
        _check_resolution(args.resolution)
        if args.d is not None:
            _check_positive("--d", args.d)
        if args.w is not None and not (math.isfinite(args.w) and args.w != 0):
            raise UsageError(f"--w: must be a finite number other than 0, got {args.w}")
    if args.command in ("reconstruct", "particles"):
        _check_input_file(args.input)
        _check_output_file(args.output)
    if args.command == "reconstruct" and args.trim is not None:
        _check_positive("--trim", args.trim)
    if args.command == "reconstruct" and args.viewpoint is not None and not all(map(math.isfinite, args.viewpoint)):
        raise UsageError(f"--viewpoint: must be three finite numbers, got {args.viewpoint}")
    if args.command == "particles":
        for option in ("radius", "cube_size", "smoothing_length", "threshold"):
            _check_positive("--" + option.replace("_", "-"), getattr(args, option))
        if args.min_particles is not None and args.min_particles < 0:
            raise UsageError(f"--min-particles: must be a non-negative integer, got {args.min_particles}")


def _summary(rows: list[tuple[str, str]]) -> str:
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"  {k:<{width}}  {v}" for k, v in rows)


def _fit_and_polygonize(kind, a, b, args):
    with step(f"fitting {'mesh' if kind == 'mesh' else 'points'} ({len(a)} points)"):
        t0 = time.perf_counter()
        if kind == "mesh":
            surface = VariationalSurface.from_mesh(a, b, d=args.d, w=args.w, kernel=args.kernel)
        else:
            exact = getattr(args, "exact", False)
            viewpoint = getattr(args, "viewpoint", None)
            if b is None and exact:
                raise UsageError("--exact: the points have no normals; the exact fit needs them (leave out --exact to estimate them)")
            if b is not None and viewpoint is not None:
                raise UsageError("--viewpoint: the points have normals; it is only used to estimate them")
            surface = VariationalSurface.fit(a, b, exact=exact, viewpoints=viewpoint, d=args.d, w=args.w, kernel=args.kernel)
        fit_s = time.perf_counter() - t0
    with step(f"polygonizing at {args.resolution}³ ({args.method})"):
        mesh = polygonize(
            surface,
            resolution=args.resolution,
            method=args.method,
            project=args.project,
            trim=getattr(args, "trim", None),
            progress=sys.stderr.isatty(),
        )
    return surface, fit_s, mesh


def _scan_rows(report) -> list[tuple[str, str]]:
    """The scan fit's report as summary rows (none for an exact fit)."""
    if not report:
        return []
    return [
        ("noise", f"{report['noise']:.3g} (estimated; spacing {report['spacing']:.3g})"),
        ("outliers", f"{report['outliers']:,} of {report['points']:,} points left out"),
        ("normals", ("estimated from the points; " if report.get("normals_estimated") else "") + f"{report['normals_corrected']:,} turned to agree with their neighbours" + (" (all turned outward)" if report["turned_outward"] else "")),
        ("distances", f"data to surface: mean {report['distance_mean']:.3g}, 99% {report['distance_p99']:.3g}, max {report['distance_max']:.3g}"),
    ]


def _report(surface, fit_s, mesh) -> str:
    tm = mesh.to_trimesh()
    st = mesh.stats
    return _summary(
        [
            ("constraints", f"{len(surface)}"),
            ("merged", f"{surface.merged_points} data points within merge_distance of another"),
            ("fit", f"{fit_s:.3f} s ({'scan, ' if surface.report else ''}{surface.method}, residual {surface.residual:.1e})"),
            *_scan_rows(surface.report),
            ("method", f"{st['method']} at {'x'.join(map(str, st['resolution']))} cells"),
            ("evaluations", f"{st['evaluations']:,} ({st['evaluation_percent']:.2f} % of plain marching cubes)"),
            ("polygonize", f"{st['seconds']['total']:.3f} s"),
            ("triangles", f"{len(mesh.faces):,}"),
            ("vertices", f"{len(mesh.vertices):,}"),
            *([("bodies dropped", f"{st['bodies_dropped']} (bubbles or voids the data disowns)")] if st.get("bodies_dropped") else []),
            *([("trimmed", f"{st['trimmed']:,} triangles farther than --trim from the data")] if "trimmed" in st else []),
            ("watertight", "yes" if tm.is_watertight else "no"),
            ("genus", f"{(2 - mesh.euler_number) // 2}"),
        ]
    )


def cmd_demo(args) -> int:
    from .plotting import render_png
    from .shapes import load_model

    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    vertices, faces = load_model(args.model)
    surface, fit_s, mesh = _fit_and_polygonize("mesh", vertices, faces, args)
    ply = out / f"{args.model}.ply"
    png = out / f"{args.model}.png"
    with step(f"writing {ply} and {png}"):
        mesh.save(ply)
        render_png(mesh, png, title=f"{args.model}: {len(mesh.faces):,} triangles")
    print(f"implicitmesh {__version__} demo: model '{args.model}' (bundled, {len(vertices)} vertices)")
    print(_report(surface, fit_s, mesh))
    print(f"  wrote        {ply}, {png}")
    return 0


def cmd_reconstruct(args) -> int:
    kind, a, b = _read_input(Path(args.input))
    surface, fit_s, mesh = _fit_and_polygonize(kind, a, b, args)
    mesh.save(args.output)
    print(_report(surface, fit_s, mesh))
    print(f"  wrote        {args.output}")
    return 0


def cmd_particles(args) -> int:
    from . import BlobField
    from .frames import read_particles

    with step(f"reading {args.input}"):
        positions = read_particles(args.input, key=args.key) if args.key else read_particles(args.input)
    kind = "anisotropic colour field" if args.anisotropic else "colour field"
    with step(f"{kind} of {len(positions):,} particles"):
        field = BlobField.from_particles(
            positions,
            args.radius,
            smoothing_length=args.smoothing_length,
            iso_surface_threshold=args.threshold,
            kernel=args.kernel,
            precision=args.precision,
            anisotropic=args.anisotropic,
        )
    lo, hi = field.bounds
    cells = max(1, int(round(float((hi - lo).max()) / (args.cube_size * args.radius))))
    with step(f"polygonizing at {cells} cells (sparse)"):
        mesh = polygonize(
            field,
            resolution=cells,
            method="sparse",
            normals=args.normals,
            min_particles=args.min_particles,
            progress=sys.stderr.isatty(),
        )
    mesh.save(args.output)
    st = mesh.stats
    box = np.asarray(st["bounds"], dtype=float)
    side = float((box[1, 0] - box[0, 0]) / st["resolution"][0])
    dropped = []
    if args.min_particles is not None:
        dropped = [("dropped", f"{st['fragments_dropped']:,} bodies of fewer than {args.min_particles} particles ({st['fragment_particles']:,} particles)")]
    print(
        _summary(
            [
                ("particles", f"{len(positions):,} ({positions.dtype})"),
                ("cells", f"{'x'.join(map(str, st['resolution']))} of side {side:.6g}"),
                ("polygonize", f"{st['seconds']['total']:.3f} s"),
                *dropped,
                ("triangles", f"{len(mesh.faces):,}"),
                ("vertices", f"{len(mesh.vertices):,}"),
                ("wrote", f"{args.output}"),
            ]
        )
    )
    return 0


def _add_fit_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--resolution", type=int, default=128, help="cells along the longest side of the box (default 128)")
    p.add_argument(
        "--method",
        choices=FIT_METHODS,
        default="octree",
        help="polygonizer for the fitted surface: octree (default), dense (every lattice point) or tracking",
    )
    p.add_argument(
        "--project",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="move the vertices onto the fitted surface by one Newton step (default: yes)",
    )
    p.add_argument("--d", type=float, default=None, help="normal constraint offset (default: 0.0075 x largest side, at most 6 x the point spacing)")
    p.add_argument("--w", type=float, default=None, help="normal constraint value (default 0.75 d)")
    p.add_argument(
        "--kernel",
        default="triharmonic",
        choices=["triharmonic", "biharmonic", "thin_plate"],
        help="radial basis function of the fit: triharmonic r^3 (default), biharmonic r, thin_plate r^2 log r",
    )


def main(argv: list[str] | None = None) -> int:
    parser = _Parser(prog="implicitmesh", description="Implicit surfaces to triangle meshes.")
    parser.add_argument("--version", action="version", version=f"implicitmesh {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="fit a bundled model, polygonize it, write a PLY and a PNG")
    demo.add_argument("--model", default="knot", choices=["knot", "spot"], help="the bundled model (default knot)")
    demo.add_argument("-o", "--output", default="implicitmesh-demo", help="output folder (default implicitmesh-demo)")
    _add_fit_options(demo)
    rec = sub.add_parser("reconstruct", help="fit a mesh or points (a scan, with or without normals) and polygonize it")
    rec.add_argument("input", help="a mesh (PLY/OBJ/STL/OFF...), a PLY point set (normals nx ny nz optional), .xyz/.txt with 3 or 6 columns, or .npz with points (and normals)")
    rec.add_argument("-o", "--output", required=True, help=f"output mesh, its format from the suffix ({', '.join(MESH_SUFFIXES)})")
    rec.add_argument(
        "--exact",
        action="store_true",
        help="points: interpolate every point (exact samples); default: the scan fit (noise, outliers and flipped normals handled, unseen regions closed). Meshes are always interpolated",
    )
    rec.add_argument(
        "--trim",
        type=float,
        default=None,
        metavar="D",
        help="drop the parts of the mesh farther than D (in the data's units) from every data point, leaving it open where no data was",
    )
    rec.add_argument(
        "--viewpoint",
        type=float,
        nargs=3,
        default=None,
        metavar=("X", "Y", "Z"),
        help="points without normals: where the sensor was, so that the estimated normals face it",
    )
    _add_fit_options(rec)
    par = sub.add_parser(
        "particles",
        help="mesh a frame of SPH particles (splashsurf's colour field, sparse marching cubes)",
    )
    par.add_argument("input", help="particle positions: .npy, .npz, .ply, or .vtk/.vtu and other meshio formats")
    par.add_argument("-o", "--output", required=True, help=f"output mesh, its format from the suffix ({', '.join(MESH_SUFFIXES)})")
    par.add_argument("--radius", type=float, required=True, help="particle radius r")
    par.add_argument(
        "--smoothing-length", type=float, default=2.0, help="kernel support 2 x this x r (default 2.0)"
    )
    par.add_argument("--cube-size", type=float, default=0.5, help="cell side as a multiple of r (default 0.5)")
    par.add_argument("--threshold", type=float, default=0.6, help="iso-surface threshold (default 0.6)")
    par.add_argument(
        "--kernel",
        default="cubic_spline",
        choices=["cubic_spline", "wendland"],
        help="SPH kernel of the colour field: cubic_spline (default) or wendland",
    )
    par.add_argument("--key", default=None, help=".npz only: the array of positions")
    par.add_argument(
        "--anisotropic",
        action="store_true",
        help="anisotropic kernels (Yu & Turk): flat water flat, thin sheets thin, lone particles round",
    )
    par.add_argument(
        "--precision", default="double", choices=["double", "single"], help="float type of the field's values (default double)"
    )
    par.add_argument(
        "--min-particles",
        type=int,
        default=None,
        metavar="K",
        help="drop the bodies of the mesh holding fewer than K particles (stray droplets)",
    )
    par.add_argument(
        "--normals", action=argparse.BooleanOptionalAction, default=True, help="vertex normals (default: yes)"
    )
    args = parser.parse_args(argv)
    try:
        _check(args)
        if args.command == "demo":
            return cmd_demo(args)
        if args.command == "particles":
            return cmd_particles(args)
        return cmd_reconstruct(args)
    except (ValueError, OSError) as e:
        print(f"implicitmesh: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
