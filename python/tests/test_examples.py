"""The quickstart example end to end (its small library): the paper's figure from Python."""

import importlib.util
import os
import pathlib

import pytest

EXAMPLE = pathlib.Path(__file__).resolve().parents[1] / "examples" / "quickstart.py"

try:
    import matplotlib  # noqa: F401

    HAVE_MATPLOTLIB = True
except ImportError:
    HAVE_MATPLOTLIB = False


@pytest.mark.skipif(
    not HAVE_MATPLOTLIB and os.environ.get("SLCP_REQUIRE_RAY") != "1",
    reason="matplotlib is not installed (bash .ci/run installs it)",
)
def test_the_quickstart_spins_the_ellipse_and_draws_the_figure(tmp_path):
    spec = importlib.util.spec_from_file_location("quickstart", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out = tmp_path / "quickstart.png"
    xs, rate = module.main(["--quick", "--seconds", "40", "--out", str(out)])
    assert out.read_bytes()[1:4] == b"PNG" and out.stat().st_size > 20_000
    assert xs.shape == (801, 6)
    # The small library's policy keeps the ellipse turning forward.
    assert rate > 0.2, rate


def test_the_documented_api_snippet_runs(tmp_path, monkeypatch):
    # docs/python.md's first code block, as a user would paste it (the default library's build, about
    # 20 s, left out), in a scratch folder with the repository's scenes.
    import re
    import shutil

    root = pathlib.Path(__file__).resolve().parents[2]
    text = (root / "docs" / "python.md").read_text()
    code = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    default_build = "lib = slcp.Library.train()  "
    assert default_build in code
    code = "\n".join(line for line in code.splitlines() if not line.startswith(default_build))
    shutil.copytree(root / "scenes", tmp_path / "scenes")
    monkeypatch.chdir(tmp_path)
    scope = {}
    exec(compile(code, "docs/python.md", "exec"), scope)
    assert scope["sol"]["task"] == "turn"
    assert scope["H"].shape == (8, 8)
    assert scope["report"]["unconverged_steps"] == 0
    # The library went to a scratch folder of its own, not into the folder the snippet ran in.
    assert pathlib.Path(scope["path"]).exists()
    assert not (tmp_path / "push.lib").exists()
