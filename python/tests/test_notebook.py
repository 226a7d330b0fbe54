"""The tour notebook (python/examples/tour.ipynb) runs from top to bottom, as a user would run it."""

import pathlib

import nbformat
import pytest
from nbclient import NotebookClient

ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_the_tour_notebook_runs_and_its_policy_spins_the_ellipse(tmp_path):
    nb = nbformat.read(ROOT / "python" / "examples" / "tour.ipynb", as_version=4)
    # Executed in a scratch folder: the notebook writes nothing, and needs no file beside it.
    NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    outputs = [o for cell in nb.cells if cell.cell_type == "code" for o in cell.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    text = "".join(o.get("text", "") for o in outputs if o.output_type == "stream")
    # The optimiser's line and the closed loop's: the small library's policy turns the ellipse forward.
    assert "passes," in text
    line = next(line for line in text.splitlines() if line.startswith("theta3 turned"))
    rate = float(line.split(";")[1].split("rad/s")[0])
    assert rate > 0.2, line
    # Every figure was drawn.
    images = [o for o in outputs if o.output_type == "display_data" and "image/png" in o.get("data", {})]
    assert len(images) >= 3, len(images)


if __name__ == "__main__":
    pytest.main([__file__])
