"""The same shard tasks on a Dask LocalCluster and in a process pool give the same bytes."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.fixtures.datasets import SHARD_MB, tree_bytes
from vtsbench.dataset.build import BuildOptions, build


def test_local_cluster_equals_process_pool(sim_recordings: Path, built: Path,
                                           tmp_path: Path) -> None:
    pytest.importorskip("distributed")
    pool = build(sim_recordings, tmp_path / "pool", BuildOptions(shard_mb=SHARD_MB, workers=2))
    dask = build(sim_recordings, tmp_path / "dask",
                 BuildOptions(shard_mb=SHARD_MB, workers=2, scheduler="local"))
    assert pool.shards_built == dask.shards_built == 11
    ref = tree_bytes(built)
    assert tree_bytes(tmp_path / "pool") == ref
    assert tree_bytes(tmp_path / "dask") == ref


def test_unreachable_scheduler_is_one_line(sim_recordings: Path, tmp_path: Path,
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("distributed")
    from vtsbench.dataset.build import execute as build_mod
    from vtsbench.errors import VtsError

    monkeypatch.setattr(build_mod, "CONNECT_TIMEOUT", "1s")
    with pytest.raises(VtsError, match=r"cannot reach the Dask scheduler at tcp://127\.0\.0\.1:9"):
        build(sim_recordings, tmp_path / "ds",
              BuildOptions(shard_mb=SHARD_MB, scheduler="tcp://127.0.0.1:9"))
    assert not (tmp_path / "ds").exists() and not (tmp_path / ".ds.partial").exists()
