"""The Ray sweep example on a local Ray instance with two workers: a tiny grid of library seeds, its
table written as CSV and Markdown."""

import csv
import importlib.util
import os
import pathlib

import pytest

HERE = pathlib.Path(__file__).resolve().parent
SWEEP = HERE.parent / "examples" / "sweep.py"

try:
    import ray  # noqa: F401

    HAVE_RAY = True
except ImportError:
    HAVE_RAY = False


def load_sweep():
    spec = importlib.util.spec_from_file_location("sweep", SWEEP)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_range_syntax():
    if not HAVE_RAY:
        pytest.skip("ray is not installed")
    sweep = load_sweep()
    assert sweep.parse_range("1-3") == [1, 2, 3]
    assert sweep.parse_range("1,4-5") == [1, 4, 5]


@pytest.mark.skipif(
    not HAVE_RAY and os.environ.get("SLCP_REQUIRE_RAY") != "1",
    reason="ray is not installed (bash .ci/run installs it)",
)
def test_a_tiny_grid_runs_on_two_local_workers(tmp_path):
    sweep = load_sweep()
    root = HERE.parents[1]
    out = tmp_path / "sweep"
    rows, wall = sweep.main(
        [
            "--num-cpus", "2",
            "--scenes", str(root / "scenes" / "pushing.toml"),
            "--seeds", "1-2",
            "--sigmas", "0.05,0.1",
            "--trajectories", "8", "--trunk", "6", "--settle", "1", "--length", "2",
            "--seconds", "5",
            "--out", str(out),
        ]
    )
    # Two seeds by two sigmas, each on its own world and on hard contact.
    assert len(rows) == 8
    with open(out.with_suffix(".csv")) as f:
        table = list(csv.DictReader(f))
    assert len(table) == 8
    assert {r["world"] for r in table} == {"own", "hard"}
    assert {r["sigma"] for r in table} == {"0.05", "0.1"}
    assert all(r["unconverged"] == "0" for r in table)
    assert all(float(r["target_distance"]) >= 0.0 for r in table)
    text = out.with_suffix(".md").read_text()
    assert text.startswith("| scene |") and "grid points on 2 CPUs" in text
