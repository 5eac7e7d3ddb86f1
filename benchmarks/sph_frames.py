"""Frames of a real fluid simulation for the particle benchmarks: SPlisHSPlasH's dam break.

SPlisHSPlasH (``pip install pysplishsplash``) simulates its shipped ``DamBreakModel.json`` scene
(DFSPH, a box 4 × 3 × 1.5 m, gravity along -y) with the fluid block enlarged to 1 × 1 × 1.4 m (the
box's full depth but for 5 cm at each side wall) and the particle radius of the scene's name:

- ``dam-break-1e5``: particle radius 0.0125 m (83,655 particles), a few minutes;
- ``dam-break-5e5``: particle radius 0.007 m (485,100 particles), tens of minutes.

The particle positions of the frames at :data:`FRAME_TIMES` (the wave running along the floor,
hitting the far wall at about 0.85 s and climbing it) are saved as float32 ``.npy`` files, **z up** (the
simulation's (x, y, z) stored as (x, -z, y): the floor is z = 0, the box spans x in [-2, 2], y in
[-0.75, 0.75]), in ``CACHE/NAME/t0.700.npy``, beside ``CACHE/NAME/scene.json`` (particle radius,
counts, the frames' exact times, the box). The cache is ``~/.cache/implicitmesh/sph`` unless
``--frames DIR`` (or :envvar:`IMPLICITMESH_SPH_FRAMES`) says otherwise; frames already there are
used again.

The simulation runs in a subprocess: on Debian ``pysplishsplash`` imports only with
``LD_PRELOAD=/lib/x86_64-linux-gnu/libGLdispatch.so.0`` (set there when the file exists), and it
runs headless through ``SimulatorBase.run()`` with a time-step callback that saves the frames.

    python -m benchmarks.sph_frames [--frames DIR] [NAME ...]      # makes the frames that are missing
    python -m benchmarks.sph_frames --list [--frames DIR]          # the frames in the cache
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: Particle radius (m) of each scene.
SCENES = {"dam-break-1e5": 0.0125, "dam-break-5e5": 0.007}
#: Simulated times (s) of the saved frames of each scene: the wave's front runs along the floor
#: (at x = 0.7 m at 0.5 s), reaches the far wall (x = 2 m) at about 0.85 s and climbs it.
FRAME_TIMES = {"dam-break-1e5": (0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.2), "dam-break-5e5": (0.6, 0.7, 0.8)}
#: The fluid block (simulation coordinates, before the scene's translation [-1.45, 0.05, 0]).
BLOCK = {"start": [-0.5, 0.0, -0.7], "end": [0.5, 1.0, 0.7]}
#: The container, z up: (min, max) corners of the box's inside (m).
BOX = ((-2.0, -0.75, 0.0), (2.0, 0.75, 3.0))
#: The library Debian's GL dispatch needs preloaded before ``pysplishsplash`` imports.
GL_DISPATCH = "/lib/x86_64-linux-gnu/libGLdispatch.so.0"
ENV_CACHE = "IMPLICITMESH_SPH_FRAMES"


def cache_dir(frames: str | os.PathLike | None = None) -> Path:
    """The frames' directory: ``frames``, else ``$IMPLICITMESH_SPH_FRAMES``, else
    ``~/.cache/implicitmesh/sph``."""
    if frames:
        return Path(frames).expanduser().resolve()
    if os.environ.get(ENV_CACHE):
        return Path(os.environ[ENV_CACHE]).expanduser().resolve()
    return Path.home() / ".cache" / "implicitmesh" / "sph"


def frame_name(t: float) -> str:
    """The file name of the frame at time ``t``: ``t0.700.npy``."""
    return f"t{t:.3f}.npy"


def check_scene(name: str) -> None:
    """Refuses a scene this module does not know (ValueError naming the choices)."""
    if name not in SCENES:
        raise ValueError(f"unknown scene {name!r}; choose from {', '.join(SCENES)}")


def scene_info(name: str, frames: str | os.PathLike | None = None) -> dict | None:
    """``scene.json`` of a scene in the cache (particle radius, particles, frames and their
    times), or None when the scene has not been simulated."""
    check_scene(name)
    path = cache_dir(frames) / name / "scene.json"
    return json.loads(path.read_text()) if path.exists() else None


def frame_paths(name: str, frames: str | os.PathLike | None = None) -> list[Path]:
    """The saved frames of a scene, in time order ([] when there are none)."""
    info = scene_info(name, frames)
    if info is None:
        return []
    d = cache_dir(frames) / name
    return [d / f["file"] for f in info["frames"] if (d / f["file"]).exists()]


def load_frame(name: str, time_s: float, frames: str | os.PathLike | None = None):
    """The particles of one frame, float64 (P, 3), z up."""
    import numpy as np

    check_scene(name)
    path = cache_dir(frames) / name / frame_name(time_s)
    if not path.exists():
        raise ValueError(f"no frame at time {time_s} of {name!r} in {path.parent}; "
                         f"make it with `python -m benchmarks.sph_frames {name}`")
    return np.load(path).astype(np.float64)


def scene_file(name: str, out: Path) -> Path:
    """The dam-break scene for ``name`` written into ``out``: the shipped scene with the particle
    radius of ``name``, the enlarged fluid block and absolute model paths."""
    shipped = Path(sys.executable).parent / "data" / "Scenes" / "DamBreakModel.json"
    if not shipped.exists():
        raise FileNotFoundError(f"{shipped} is missing: install pysplishsplash into this Python's environment")
    scene = json.loads(shipped.read_text())
    scene["Configuration"]["particleRadius"] = SCENES[name]
    for body in scene["RigidBodies"]:
        body["geometryFile"] = str((shipped.parent / body["geometryFile"]).resolve())
    scene["FluidBlocks"][0].update(BLOCK)
    path = out / f"{name}.json"
    path.write_text(json.dumps(scene, indent=1))
    return path


def simulate(name: str, directory: Path) -> None:
    """Runs the simulation in this process (``pysplishsplash`` imported here: the process needs
    the LD_PRELOAD of :func:`make`) and saves the frames at its :data:`FRAME_TIMES` into ``directory``."""
    import numpy as np
    import pysplishsplash as sph

    directory.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="sph_") as tmp:
        scene = scene_file(name, Path(tmp))
        base = sph.Exec.SimulatorBase()
        base.init(useGui=False, sceneFile=str(scene), outputDir=str(Path(tmp) / "output"))
        todo = sorted(FRAME_TIMES[name])
        base.setValueFloat(base.STOP_AT, todo[-1] + 0.002)
        saved: list[dict] = []
        start = time.perf_counter()

        def step() -> None:
            tm = sph.TimeManager.getCurrent()
            t = tm.getTime()
            if not todo or t + 1e-6 < todo[0]:
                return
            fluid = sph.Simulation.getCurrent().getFluidModel(0)
            n = fluid.numActiveParticles()
            p = np.array(fluid.getFieldBuffer("position"), dtype=np.float32)[:n]
            z_up = np.ascontiguousarray(np.stack([p[:, 0], -p[:, 2], p[:, 1]], axis=1))
            target = todo.pop(0)
            np.save(directory / frame_name(target), z_up)
            saved.append({"file": frame_name(target), "time": target, "simulated_time": float(t),
                          "particles": int(n), "wall_s": round(time.perf_counter() - start, 1)})
            print(f"[sph_frames] {name}: saved t = {t:.4f} s, {n:,} particles, "
                  f"{time.perf_counter() - start:.0f} s of simulation", file=sys.stderr, flush=True)
            while todo and t + 1e-6 >= todo[0]:
                todo.pop(0)
            write_info(name, directory, saved, time.perf_counter() - start)

        base.setTimeStepCB(step)
        base.run()


def write_info(name: str, directory: Path, saved: list[dict], seconds: float) -> None:
    """``scene.json``: the scene's facts and the frames saved so far (written after each frame, so
    a simulation stopped early leaves usable frames)."""
    info = {"scene": "SPlisHSPlasH DamBreakModel.json, fluid block enlarged", "name": name,
            "particle_radius": SCENES[name], "block": BLOCK, "box": BOX, "up": "z (simulation y)",
            "solver": f"pysplishsplash {_version('pysplishsplash')}", "frames": saved,
            "simulation_wall_s": round(seconds, 1)}
    (directory / "scene.json").write_text(json.dumps(info, indent=1) + "\n")


def _version(module: str) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(module)
    except PackageNotFoundError:
        return "unknown"


def make(name: str, frames: str | os.PathLike | None = None, force: bool = False) -> list[Path]:
    """The frames of ``name``, simulated in a subprocess when they are not in the cache yet."""
    check_scene(name)
    directory = cache_dir(frames) / name
    paths = frame_paths(name, frames)
    if paths and not force:
        return paths
    env = dict(os.environ)
    if os.path.exists(GL_DISPATCH):
        env["LD_PRELOAD"] = " ".join(x for x in (GL_DISPATCH, env.get("LD_PRELOAD", "")) if x)
    root = Path(__file__).resolve().parent.parent
    print(f"[sph_frames] simulating {name} into {directory}", file=sys.stderr, flush=True)
    subprocess.run([sys.executable, "-m", "benchmarks.sph_frames", "--simulate", name, "--frames",
                    str(cache_dir(frames))], env=env, check=True, cwd=root, stdout=subprocess.DEVNULL)
    return frame_paths(name, frames)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("names", nargs="*", metavar="NAME", help=f"scenes to make (default all: {', '.join(SCENES)})")
    p.add_argument("--frames", default=None, metavar="DIR", help="the frames' cache directory")
    p.add_argument("--list", action="store_true", help="list the frames in the cache")
    p.add_argument("--force", action="store_true", help="simulate again even when frames exist")
    p.add_argument("--simulate", default=None, metavar="NAME", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.simulate:
        simulate(a.simulate, cache_dir(a.frames) / a.simulate)
        return 0
    names = a.names or list(SCENES)
    for name in names:
        check_scene(name)
    for name in names:
        if a.list:
            info = scene_info(name, a.frames)
            frames = [] if info is None else info["frames"]
            print(f"{name}: " + (", ".join(f"{f['file']} ({f['particles']:,} particles)" for f in frames)
                                 if frames else "no frames"))
        else:
            print("\n".join(str(x) for x in make(name, a.frames, a.force)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
