"""vtsbench.create after a crash: a write or rename that fails at each step in turn, and a
SIGKILL mid-episode. OUT never exists half-written, every episode saved before the crash
survives `resume=True`, and the finished dataset has the bytes of one written in one go."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

import vtsbench
from tests.fixtures.datasets import tree_bytes
from tests.fixtures.episodes import FPS, SHARD_MB, takes, write_takes
from tests.fixtures.faults import Crash, FailingOs, count_renames, run_killed
from vtsbench import atomic
from vtsbench.dataset.build.staging import partial_path
from vtsbench.errors import VtsError


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, int]:
    """The dataset written in one go, and how many renames writing it took."""
    out = tmp_path_factory.mktemp("ref") / "ds"
    with pytest.MonkeyPatch.context() as mp:
        return out, count_renames(mp, lambda: write_takes(out, takes(), name="ds"))


def test_a_failure_at_every_write_and_rename_then_resume(
        reference: tuple[Path, int], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    ref, steps = reference
    assert steps > 20
    eps = takes()
    for at in range(1, steps + 1):
        out = tmp_path / f"run{at}" / "ds"
        failing = FailingOs(at)
        monkeypatch.setattr(atomic, "os", failing)
        saved = 0
        w = None
        try:
            w = vtsbench.create(out, fps=FPS, shard_mb=SHARD_MB, sensor="gelsight-mini",
                                name="ds")
            for ep in eps:
                w.add_episode(**ep)
                saved += 1
            w.finish()
            raise AssertionError(f"no failure at step {at}")
        except Crash:
            pass
        finally:
            if w is not None:
                w.close()  # what a killed process's exit does: the lock let go
            monkeypatch.setattr(atomic, "os", os)
        assert not out.exists(), f"step {at}: OUT exists after a failed write"
        w2 = vtsbench.create(out, fps=FPS, shard_mb=SHARD_MB, sensor="gelsight-mini",
                             name="ds", resume=True)
        try:
            assert w2.episodes >= saved, f"step {at}: {saved} saved, {w2.episodes} resumed"
            for ep in eps[w2.episodes:]:
                w2.add_episode(**ep)
            w2.finish()
        finally:
            w2.close()
        assert tree_bytes(out) == tree_bytes(ref), f"step {at}: other bytes after resume"
        assert not partial_path(out).exists()


def test_sigkill_mid_episode_loses_that_episode_only(reference: tuple[Path, int],
                                                     tmp_path: Path) -> None:
    if not hasattr(signal, "SIGKILL"):
        pytest.skip("needs SIGKILL")
    out = tmp_path / "ds"
    run_killed(f"""
        import vtsbench
        from tests.fixtures.episodes import FPS, SHARD_MB, takes
        eps = takes()
        w = vtsbench.create({str(out)!r}, fps=FPS, shard_mb=SHARD_MB, sensor="gelsight-mini",
                            name="ds")
        for ep in eps[:2]:
            w.add_episode(**ep)
        third = eps[2]
        for i in range(15):  # past a shard boundary: a full shard of unsaved frames written
            w.add_frame(third["frames"][i], timestamp=third["timestamps"][i])
    """)
    assert not out.exists() and partial_path(out).is_dir()
    assert not (partial_path(out) / "meta" / "info.json").exists()
    with pytest.raises(VtsError, match="2 episode"):
        vtsbench.create(out, fps=FPS, shard_mb=SHARD_MB)
    w = vtsbench.create(out, fps=FPS, shard_mb=SHARD_MB, sensor="gelsight-mini", name="ds",
                        resume=True)
    try:
        assert (w.episodes, w.frames, w.pending) == (2, 22, 0)
        for ep in takes()[2:]:
            w.add_episode(**ep)
        w.finish()
    finally:
        w.close()
    assert tree_bytes(out) == tree_bytes(reference[0])
