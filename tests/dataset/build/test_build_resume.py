"""Atomic, resumable builds: SIGKILL at a random moment, rerun, same bytes; changed inputs."""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.fixtures.cli import cli
from tests.fixtures.datasets import BUILD_ARGS, SHARD_MB, tree_bytes
from tests.fixtures.recordings import copy_recordings
from vtsbench.dataset.build import WORK, BuildOptions, build, partial_path
from vtsbench.dataset.build import execute as build_mod

pytestmark = pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")


def _start(rec: Path, out: Path) -> subprocess.Popen[bytes]:
    return subprocess.Popen([sys.executable, "-m", "vtsbench", "build", str(rec), str(out),
                             "--workers", "1", *BUILD_ARGS], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)


def _wait(proc: subprocess.Popen[bytes], out: Path, until, timeout: float = 60.0) -> None:
    """Poll until `until()` holds, checking that OUT never exists beside its partial build."""
    partial = partial_path(out)
    t0 = time.monotonic()
    while not until():
        assert not (out.exists() and partial.exists())
        assert proc.poll() is None, "the build ended before it could be killed"
        assert time.monotonic() - t0 < timeout
        time.sleep(0.005)


def _markers(out: Path) -> list[Path]:
    return sorted((partial_path(out) / WORK / "shards").glob("*.json"))


def test_sigkill_after_some_shards_then_resume(sim_recordings: Path, built: Path,
                                               tmp_path: Path) -> None:
    out = tmp_path / "ds"
    proc = _start(sim_recordings, out)
    try:
        _wait(proc, out, lambda: len(_markers(out)) >= 1)
        time.sleep(random.Random(20240607).uniform(0.0, 0.15))
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait()
    assert not out.exists()
    assert partial_path(out).is_dir()
    done = len(_markers(out))
    assert done >= 1
    res = cli("build", str(sim_recordings), str(out), "--workers", "1", *BUILD_ARGS[:-1])
    assert res.returncode == 0, res.stderr
    assert f"resuming .ds.partial: {done} of 11 shards already done" in res.stderr
    assert not partial_path(out).exists()
    assert tree_bytes(out) == tree_bytes(built)


def test_sigkill_before_any_shard_then_resume(sim_recordings: Path, built: Path,
                                              tmp_path: Path) -> None:
    out = tmp_path / "ds"
    proc = _start(sim_recordings, out)
    try:
        _wait(proc, out, lambda: partial_path(out).is_dir())
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait()
    assert not out.exists()
    assert not _markers(out)
    res = cli("build", str(sim_recordings), str(out), "--workers", "1", *BUILD_ARGS)
    assert res.returncode == 0, res.stderr
    assert tree_bytes(out) == tree_bytes(built)


def _interrupt_after(monkeypatch: pytest.MonkeyPatch, n: int) -> None:
    """Make the n+1-th shard task raise KeyboardInterrupt (an in-process Ctrl-C)."""
    real, calls = build_mod.run_shard, []

    def stop(task):
        calls.append(task)
        if len(calls) > n:
            raise KeyboardInterrupt
        return real(task)

    monkeypatch.setattr(build_mod, "run_shard", stop)


def test_changed_source_rebuilds_only_its_shard(sim_recordings: Path, built: Path,
                                                tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    rec = copy_recordings(sim_recordings, tmp_path / "rec")
    out = tmp_path / "ds"
    opts = BuildOptions(shard_mb=SHARD_MB)
    with monkeypatch.context() as m:
        _interrupt_after(m, 4)
        with pytest.raises(KeyboardInterrupt):
            build(rec, out, opts)
    assert not out.exists() and len(_markers(out)) == 4
    # same bytes, new modification time: the first static shard is redone, the others kept
    st = rec / "static" / "static-00001.png"
    os.utime(st, ns=(st.stat().st_atime_ns, st.stat().st_mtime_ns + 10**9))
    res = build(rec, out, opts)
    assert (res.shards_kept, res.shards_built) == (3, 8)
    assert tree_bytes(out) == tree_bytes(built)


def test_changed_parameter_restarts_the_shards(sim_recordings: Path, tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "ds"
    with monkeypatch.context() as m:
        _interrupt_after(m, 3)
        with pytest.raises(KeyboardInterrupt):
            build(sim_recordings, out, BuildOptions(shard_mb=SHARD_MB))
    res = build(sim_recordings, out, BuildOptions(shard_mb=SHARD_MB, compression_level=1))
    assert (res.shards_kept, res.shards_built) == (0, 11)
    fresh = tmp_path / "fresh"
    build(sim_recordings, fresh, BuildOptions(shard_mb=SHARD_MB, compression_level=1))
    assert tree_bytes(out) == tree_bytes(fresh)
