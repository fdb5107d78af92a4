"""`vtsbench simulate-episodes`: the command, its one-line refusals, and a run killed at a
write or rename that resumes to the bytes of a run in one go."""

from __future__ import annotations

import dataclasses
import inspect
import os
from pathlib import Path

import pytest
from typer.testing import CliRunner

import vtsbench
from tests.fixtures.datasets import tree_bytes
from tests.fixtures.faults import Crash, FailingOs, count_renames
from vtsbench import atomic
from vtsbench.cli import app
from vtsbench.cli.episodes import simulate_episodes as command
from vtsbench.dataset.build.staging import partial_path
from vtsbench.errors import VtsError
from vtsbench.sim.episode_dataset import (
    MAX_SAMPLE_STRIDE,
    SAMPLE_STRIDE,
    EpisodeOptions,
    simulate_episodes,
)

ARGS = ["--episodes", "8", "--objects", "2", "--sessions", "2", "--fps", "25", "--seconds", "3",
        "--size", "48x64", "--quiet"]
OPTS = EpisodeOptions(8, 2, 2, 25.0, 3.0, (48, 64), 0)


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, int]:
    """The command's dataset written in one go, and how many renames it took."""
    out = tmp_path_factory.mktemp("ref") / "ds"
    runs = []
    with pytest.MonkeyPatch.context() as mp:
        renames = count_renames(mp, lambda: runs.append(
            CliRunner().invoke(app, ["simulate-episodes", str(out), *ARGS])))
    res = runs[0]
    assert res.exit_code == 0, res.output
    assert "wrote 8 takes of 3 s at 25 fps" in res.output
    return out, renames


def test_the_command_writes_takes_and_samples(reference: tuple[Path, int]) -> None:
    ds = vtsbench.load(reference[0])
    assert len(ds.episodes) == 8 and len(ds.view("slip")) > 10
    assert "episode_unseen_objects" in ds.splits and "unseen_objects" in ds.splits
    onsets = ds.episodes.index.column("slip_onset_s").to_pylist()
    assert sum(o is None for o in onsets) == 2  # a quarter of the takes hold without slip


def test_sample_stride(reference: tuple[Path, int], tmp_path: Path) -> None:
    out = tmp_path / "dense"
    res = CliRunner().invoke(app, ["simulate-episodes", str(out), *ARGS, "--sample-stride", "2"])
    assert res.exit_code == 0, res.output
    starts = {v: [int(s[-6:]) for s in vtsbench.load(p).view("slip").index.column(
        "sample_id").to_pylist()] for v, p in (("dense", out), ("default", reference[0]))}
    assert all(a % SAMPLE_STRIDE == 0 for a in starts["default"])
    assert all(a % 2 == 0 for a in starts["dense"]) and any(a % 4 for a in starts["dense"])
    # the takes are the same; the stride is in the options a resume must match
    assert (vtsbench.load(out).episodes[0]["rgb"] == vtsbench.load(reference[0]).episodes[0]
            ["rgb"]).all()
    assert dataclasses.replace(OPTS, sample_stride=2).key() != OPTS.key()
    # the command's default and bound are the library's
    param = inspect.signature(command, eval_str=True).parameters["sample_stride"]
    assert param.default == SAMPLE_STRIDE
    assert param.annotation.__metadata__[0].max == MAX_SAMPLE_STRIDE


def test_killed_at_any_rename_then_resumed(reference: tuple[Path, int], tmp_path: Path,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    ref, steps = reference
    assert steps > 8
    for at in sorted({1, 2, 3, steps // 3, steps // 2, steps - 2, steps - 1, steps}):
        out = tmp_path / f"run{at}" / "ds"
        monkeypatch.setattr(atomic, "os", FailingOs(at))
        with pytest.raises(Crash):
            simulate_episodes(out, OPTS)
        monkeypatch.setattr(atomic, "os", os)
        assert not out.exists(), f"step {at}: OUT exists after a failed run"
        res = CliRunner().invoke(app, ["simulate-episodes", str(out), *ARGS])
        assert res.exit_code == 0, f"step {at}: {res.output}"
        assert tree_bytes(out) == tree_bytes(ref), f"step {at}: other bytes after resume"
        assert not partial_path(out).exists()


def test_a_resume_with_other_options_and_bad_options(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "ds"
    monkeypatch.setattr(atomic, "os", FailingOs(12))
    with pytest.raises(Crash):
        simulate_episodes(out, OPTS)
    monkeypatch.setattr(atomic, "os", os)
    other = EpisodeOptions(8, 2, 2, 25.0, 3.0, (48, 64), seed=1)
    with pytest.raises(VtsError, match="simulated with other options"):
        simulate_episodes(out, other)
    runner = CliRunner()
    for args, match in ((["--seconds", "1"], "at least"), (["--size", "8x8"], "too small"),
                        (["--episodes", "0"], "episodes"),
                        (["--sample-stride", "0"], "sample-stride"),
                        (["--sample-stride", "65"], "sample-stride")):
        res = runner.invoke(app, ["simulate-episodes", str(tmp_path / "x"), *ARGS, *args])
        assert res.exit_code != 0
        assert match in res.output, res.output
