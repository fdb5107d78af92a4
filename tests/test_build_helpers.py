"""Shared fixtures of the build tests: small simulated recordings with a lut calibration, and one
reference dataset built from them (both read-only: copy before changing anything).

Test modules use them with `pytest_plugins = ["test_build_helpers"]`.
"""

from __future__ import annotations

import hashlib
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

SIZE = (96, 128)
#: Small shards so that both kinds have several, the last one partial (static: 4 per shard).
SHARD_MB = 0.15
BUILD_ARGS = ("--shard-mb", str(SHARD_MB), "--quiet")


def make_recordings(root: Path) -> Path:
    """Simulate 6 static frames, 9 sequences of 8 frames and 6 presses, then calibrate (lut)
    with `vtsbench calibrate RECORDINGS --out RECORDINGS/calibration.safetensors`."""
    from typer.testing import CliRunner

    from vtsbench.cli import app
    from vtsbench.sim.simulate import simulate

    simulate(root, seed=3, n_static=6, n_sequences=9, n_presses=6, size=SIZE, mm_per_px=0.08,
             n_sessions=3, progress=False)
    res = CliRunner().invoke(app, ["calibrate", str(root), "--out",
                                   str(root / "calibration.safetensors"), "--method", "lut"])
    assert res.exit_code == 0, res.output
    return root


def tree_bytes(root: Path) -> dict[str, str]:
    """sha256 of every file under root, hidden ones included, by relative path."""
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def copy_recordings(src: Path, dst: Path) -> Path:
    """A private copy of a recordings folder that a test may break."""
    return Path(shutil.copytree(src, dst))


def cli(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    """Run `python -m vtsbench ARGS` and capture its output."""
    return subprocess.run([sys.executable, "-m", "vtsbench", *args], capture_output=True,
                          text=True, timeout=timeout)


@pytest.fixture(scope="session")
def sim_recordings(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Simulated recordings with calibration.safetensors (read-only)."""
    return make_recordings(tmp_path_factory.mktemp("build-rec") / "rec")


@pytest.fixture(scope="session")
def built(sim_recordings: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The reference dataset: built in this process with one worker (read-only)."""
    from vtsbench.dataset.build import BuildOptions, build

    out = tmp_path_factory.mktemp("build-ref") / "ds"
    build(sim_recordings, out, BuildOptions(shard_mb=SHARD_MB))
    return out
