"""Executes every notebook in notebooks/ from top to bottom (in memory; the files are not changed).

A notebook fails the test when any of its cells raises. The kernel is this interpreter (the one running
pytest, so the package under test), whatever "python3" kernels are installed elsewhere: the test writes a
kernelspec for ``sys.executable`` into a temporary folder and hands nbclient a kernel manager that only
looks there. Skipped, with the reason, only when ipykernel, nbclient or nbformat is missing; pictures need an off-screen OpenGL for pyvista (see README), and without one the
notebooks fail rather than skip.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from conftest import require_mesh_dir

NOTEBOOK_DIR = Path(__file__).resolve().parents[1] / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))
CELL_TIMEOUT = 600  # seconds per cell


def test_notebooks_are_present_and_saved_without_outputs():
    nbformat = pytest.importorskip("nbformat", reason="nbformat is not installed (pip install '.[test]')")
    names = {p.name for p in NOTEBOOKS}
    assert {"cuno_distance.ipynb", "cuno_tables.ipynb", "jin_subdivision.ipynb", "triquet_blobs.ipynb",
            "reconstruction_at_scale.ipynb"} <= names, names
    for path in NOTEBOOKS:
        nb = nbformat.read(path, as_version=4)
        nbformat.validate(nb)
        for cell in nb.cells:
            if cell.cell_type == "code":
                assert not cell.get("outputs") and cell.get("execution_count") is None, f"{path.name}: outputs not stripped"


@pytest.fixture(scope="module")
def kernel_dir(tmp_path_factory) -> Path:
    """A kernels/ folder with a "python3" kernelspec that runs this interpreter."""
    pytest.importorskip("ipykernel", reason="ipykernel is not installed, so no kernel can run the notebooks (pip install '.[test]')")
    kernels = tmp_path_factory.mktemp("jupyter") / "kernels"
    spec = kernels / "python3"
    spec.mkdir(parents=True)
    (spec / "kernel.json").write_text(
        json.dumps(
            {
                "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
                "display_name": f"Python {sys.version_info.major}.{sys.version_info.minor} (test interpreter)",
                "language": "python",
            }
        )
    )
    return kernels


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs(path, kernel_dir):
    nbformat = pytest.importorskip("nbformat", reason="nbformat is not installed (pip install '.[test]')")
    nbclient = pytest.importorskip("nbclient", reason="nbclient is not installed (pip install '.[test]')")
    from jupyter_client.kernelspec import KernelSpecManager
    from jupyter_client.manager import KernelManager

    require_mesh_dir()  # the notebooks read tests/data/meshes
    specs = KernelSpecManager(kernel_dirs=[str(kernel_dir)], ensure_native_kernel=False)
    assert specs.get_kernel_spec("python3").argv[0] == sys.executable
    km = KernelManager(kernel_name="python3", kernel_spec_manager=specs)

    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(
        nb,
        km=km,
        kernel_name="python3",
        timeout=CELL_TIMEOUT,
        resources={"metadata": {"path": str(NOTEBOOK_DIR)}},  # the kernel's working directory
    )
    try:
        # Raises CellExecutionError (with the cell and its traceback) when a cell fails; cleanup_kc
        # shuts the kernel down afterwards, which nbclient only does by itself for managers it made.
        client.execute(cleanup_kc=True)
    finally:
        if km.has_kernel:
            km.shutdown_kernel(now=True)
    assert any(cell.get("outputs") for cell in nb.cells if cell.cell_type == "code")
