"""docs/tutorial.ipynb runs from top to bottom (nbclient, a kernel of this Python), so the
tutorial never rots: every cell without an error, the plan found, checked, simulated, written
and read back, and Meshcat opened on the loopback interface, as its summary cell states.

The kernel runs in a temporary directory (the notebook writes its pictures and plan file
there) with this checkout on its PYTHONPATH and the environment of the test (LCM_DEFAULT_URL,
RBP_THREADS). Its kernelspec points at this interpreter, so a `python3` kernel installed
elsewhere on the machine is never picked up instead.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path
from urllib.parse import urlparse

import pytest

nbformat = pytest.importorskip("nbformat", reason="the test extra's nbclient runs the tutorial")
nbclient = pytest.importorskip("nbclient", reason="the test extra's nbclient runs the tutorial")
pytest.importorskip("ipykernel", reason="the test extra's ipykernel runs the tutorial's kernel")

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOK = ROOT / "docs" / "tutorial.ipynb"
KERNEL = "rbp-tutorial"
CELL_TIMEOUT = 300  # s per cell: the first plan of a fresh checkout compiles the kernel (~1 min)
MARKER = "TUTORIAL SUMMARY "


def test_committed_notebook_has_no_outputs() -> None:
    """The committed notebook is its source only (outputs would go stale and bloat diffs)."""
    nb = nbformat.read(NOTEBOOK, as_version=4)
    nbformat.validate(nb)
    stale = [k for k, cell in enumerate(nb.cells) if cell.cell_type == "code"
             and (cell.outputs or cell.execution_count is not None)]
    assert not stale, f"cells {stale} of {NOTEBOOK.name} carry outputs: clear them"


def _kernelspec(where: Path) -> Path:
    """A kernelspec named KERNEL that runs ipykernel in this interpreter."""
    spec = where / "kernels" / KERNEL
    spec.mkdir(parents=True)
    (spec / "kernel.json").write_text(json.dumps({
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "rbp tutorial", "language": "python"}))
    return where


def test_tutorial_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    nb = nbformat.read(NOTEBOOK, as_version=4)
    monkeypatch.setenv("JUPYTER_PATH", str(_kernelspec(tmp_path / "jupyter")))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]))
    monkeypatch.setenv("LCM_DEFAULT_URL", os.environ.get("LCM_DEFAULT_URL", "memq://"))
    monkeypatch.setenv("MPLBACKEND", "Agg")
    work = tmp_path / "work"
    work.mkdir()
    client = nbclient.NotebookClient(nb, kernel_name=KERNEL, timeout=CELL_TIMEOUT,
                                     resources={"metadata": {"path": str(work)}})
    start = time.perf_counter()
    client.execute()  # raises CellExecutionError, with the cell and its traceback, on an error
    seconds = time.perf_counter() - start

    errors = [out for cell in nb.cells if cell.cell_type == "code" for out in cell.outputs
              if out.output_type == "error"]
    assert not errors, f"cells raised: {[e.ename for e in errors]}"
    text = "".join(out.get("text", "") for cell in nb.cells if cell.cell_type == "code"
                   for out in cell.outputs if out.output_type == "stream")
    lines = [ln for ln in text.splitlines() if ln.startswith(MARKER)]
    assert len(lines) == 1, f"the summary cell printed {len(lines)} summaries:\n{text[-2000:]}"
    summary = json.loads(lines[0][len(MARKER):])
    assert summary["plan_success"] is True and summary["problems"] == 0, summary
    assert summary["simulated_success"] is True and summary["read_back_equal"] is True, summary
    assert summary["trials"] == 20 and 0 <= summary["successes"] <= 20, summary
    assert 0 < summary["p_path"] <= 1, summary
    lo, hi = summary["ci95"]
    assert lo <= summary["rate"] <= hi, summary
    assert urlparse(summary["meshcat_url"]).hostname in ("localhost", "127.0.0.1"), summary
    # what the notebook says it wrote, in its working directory
    for name in ("cave.png", "climb.png"):
        assert (work / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    assert json.loads((work / "climb.json").read_text())["success"] is True
    assert "set_animation" in (work / "climb.html").read_text()
    pictures = [out for cell in nb.cells if cell.cell_type == "code" for out in cell.outputs
                if "image/png" in out.get("data", {})]
    assert len(pictures) == 2, f"{len(pictures)} pictures shown, the cave's and the plan's"
    print(f"the tutorial ran in {seconds:.1f} s")
