"""Shared fixtures: the repository root and the `cargo xtask` command the results are compared with."""

import json
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def root():
    return ROOT


@pytest.fixture(scope="session")
def xtask_step():
    """Run `cargo xtask step` on JSON lines and return its answers (the command-line reference)."""

    # The binary `cargo test --workspace` builds (as .ci/run runs it first), else cargo builds one.
    built = ROOT / "target" / "debug" / "xtask"
    command = [str(built)] if built.exists() else ["cargo", "run", "--quiet", "-p", "xtask", "--"]

    def run(lines, *flags):
        text = "".join(json.dumps(line) + "\n" for line in lines)
        out = subprocess.run(
            [*command, "step", *flags],
            input=text,
            capture_output=True,
            text=True,
            cwd=ROOT,
            check=True,
            timeout=1800,
        )
        return [json.loads(line) for line in out.stdout.splitlines()]

    return run
