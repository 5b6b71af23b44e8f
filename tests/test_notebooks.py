"""The notebooks in notebooks/ run headless from top to bottom, and are committed small.

Each notebook is executed with nbclient in memory (the file in the repository is never written),
with ``notebooks/`` as the working directory, in a kernel that runs this very interpreter: a
kernel spec is written to a temporary folder for the session, so neither an installed ``python3``
kernel spec nor the user's Jupyter setup is needed or touched. The executed copy is saved in the
test's temporary folder for inspection, where the kernel's temporary files go too (``TMPDIR``).
"""

from __future__ import annotations

import gc
import json
import os
import warnings
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # executes whole notebooks (the full suite runs them)

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOK_DIR = ROOT / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))

#: Longest time one cell may take [s].
CELL_TIMEOUT = 120
#: Largest committed notebook [bytes]: notebooks are committed with their outputs cleared.
MAX_NOTEBOOK_BYTES = 200_000
KERNEL_NAME = "fault-tolerance-tests"


@pytest.fixture(scope="session")
def kernel_manager_factory(tmp_path_factory):
    """``factory()`` -> a KernelManager whose kernel is ipykernel in ``sys.executable``."""
    pytest.importorskip("ipykernel")
    from ipykernel.kernelspec import write_kernel_spec
    from jupyter_client.kernelspec import KernelSpecManager
    from jupyter_client.manager import KernelManager

    kernels = tmp_path_factory.mktemp("kernels")
    write_kernel_spec(kernels / KERNEL_NAME, overrides={"display_name": "fault_tolerance tests"})
    specs = KernelSpecManager(kernel_dirs=[str(kernels)])

    def factory() -> KernelManager:
        return KernelManager(kernel_name=KERNEL_NAME, kernel_spec_manager=specs)

    return factory


def test_notebooks_exist():
    """The three story notebooks are in notebooks/."""
    names = {p.name for p in NOTEBOOKS}
    assert {"01_planar_3r.ipynb", "02_any_urdf_arm.ipynb", "03_lock_replay.ipynb"} <= names


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_committed_small(path: Path):
    """A committed notebook is nbformat 4 JSON, small, and carries no outputs."""
    size = path.stat().st_size
    assert size <= MAX_NOTEBOOK_BYTES, f"{path.name} is {size} bytes; clear its outputs"
    nb = json.loads(path.read_text(encoding="utf-8"))
    assert nb.get("nbformat") == 4, f"{path.name}: not an nbformat 4 notebook"
    code = [(i, c) for i, c in enumerate(nb["cells"]) if c["cell_type"] == "code"]
    with_outputs = [i for i, c in code if c.get("outputs") or c.get("execution_count")]
    assert not with_outputs, f"{path.name}: cells {with_outputs} have saved outputs; clear them"


def _execute(path: Path, tmp_path: Path, kernel_manager_factory):
    """``path`` executed in memory (the executed copy saved in ``tmp_path``); its error outputs."""
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")

    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(
        nb,
        km=kernel_manager_factory(),
        timeout=CELL_TIMEOUT,
        startup_timeout=120,
        allow_errors=False,
        resources={"metadata": {"path": str(NOTEBOOK_DIR)}},
    )
    try:
        # files the notebook writes to tempfile folders land in this test's tmp_path
        client.execute(env={**os.environ, "TMPDIR": str(tmp_path)})
    finally:
        nbformat.write(nb, tmp_path / path.name)  # the executed copy, for a look after a failure
        # jupyter_client leaves the kernel channels' zmq sockets to the garbage collector: collect
        # them here, or their "Unclosed socket" ResourceWarning lands in a later test's warnings
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ResourceWarning)
            gc.collect()
    errors = [
        o for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"
    ]
    return nb, errors


@pytest.mark.notebook
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_executes(path: Path, tmp_path: Path, kernel_manager_factory):
    """Every cell of the notebook runs without an error, within the cell timeout."""
    _, errors = _execute(path, tmp_path, kernel_manager_factory)
    assert not errors, json.dumps(errors, indent=1)[:4000]


def _text(cell) -> str:
    return "".join(o.get("text", "") for o in cell.outputs if o.output_type == "stream")


@pytest.mark.notebook
def test_interactive_notebook_shows_widgets_and_their_effect(
    tmp_path: Path, kernel_manager_factory
):
    """05: the controls are displayed as widgets, driving them changes the lock and its jump (the
    numbers an explorer with the same settings gives here), and the figure is drawn."""
    pytest.importorskip("ipywidgets")
    from fault_tolerance.viz.explorer import Explorer

    nb, errors = _execute(NOTEBOOK_DIR / "05_interactive.ipynb", tmp_path, kernel_manager_factory)
    assert not errors, json.dumps(errors, indent=1)[:4000]
    code = [c for c in nb.cells if c.cell_type == "code"]
    shown = [c for c in code if c.source.strip() == "ex.widgets()"]
    assert shown and any(
        "application/vnd.jupyter.widget-view+json" in o.get("data", {}) for o in shown[0].outputs
    )
    driven = _text(next(c for c in code if 'c["lock_time"].value = 0.5' in c.source)).splitlines()
    ex = Explorer("planar_3r", algorithm="lnva", lock_time=0.5)
    expected = [ex.describe()]
    ex.update(algorithm="jvja")
    expected.append(ex.describe())
    ex.update(lock_joint="joint2")
    expected.append(ex.describe())
    assert driven == expected
    assert len({line.rsplit("=", 1)[1] for line in driven}) == 3  # three different jumps
    last = code[-1]
    assert any("image/png" in o.get("data", {}) for o in last.outputs)
