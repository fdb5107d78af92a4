"""The read limit of a split file (`dataset_split_limits`): one size from info.json, the
samples of every kind plus the episodes, used alike by the loader and verify."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import pytest

import vtsbench
from tests.fixtures.damage import rehash
from vtsbench.dataset.format.info import load_info
from vtsbench.dataset.splits.files import dataset_split_limits, split_limits
from vtsbench.dataset.tools.verify import verify
from vtsbench.errors import VtsError

#: The views dataset: 5 static and 8 slip samples on 3 episodes (42 frames).
SAMPLES, EPISODES = 5 + 8, 3


def test_samples_of_every_kind_plus_episodes(views_dataset: Path) -> None:
    info = load_info(views_dataset)
    assert info.episodes is not None and info.episodes.frames == 42
    assert dataset_split_limits(info) == split_limits(SAMPLES + EPISODES)


def test_the_loader_and_verify_read_splits_with_one_limit(views_dataset: Path,
                                                          monkeypatch: pytest.MonkeyPatch
                                                          ) -> None:
    """Every split of a dataset with episodes (splits of samples and of episodes) is read
    with the same limits by both."""
    import vtsbench.dataset.read.loader as loader
    import vtsbench.dataset.splits.files as files

    seen: dict[str, set[tuple[Any, Any]]] = {"load": set(), "verify": set()}

    def spy(who: str, real: Any) -> Any:
        def read(path: Any, *args: Any, **kw: Any) -> Any:
            seen[who].add((kw["max_bytes"], kw["max_ids"]))
            return real(path, *args, **kw)
        return read

    monkeypatch.setattr(loader, "read_split", spy("load", loader.read_split))
    ds = vtsbench.load(views_dataset)
    for name in ds.splits:
        ds.split_file(name)
    monkeypatch.setattr(files, "read_split", spy("verify", files.read_split))
    assert verify(views_dataset, decode=False).ok
    assert seen["load"] == seen["verify"] == {split_limits(SAMPLES + EPISODES)}


def test_a_split_over_the_limit_is_the_same_line_in_both(views_dataset: Path,
                                                         tmp_path: Path) -> None:
    ds = Path(shutil.copytree(views_dataset, tmp_path / "views"))
    path = ds / "meta" / "splits" / "seen.json"
    doc = json.loads(path.read_text())
    n = SAMPLES + EPISODES + 1
    doc["parts"] = {"train": [f"x{i}" for i in range(n)]}
    path.write_text(json.dumps(doc))
    rehash(ds)
    line = f"lists {n} sample ids, more than the {n - 1} samples of the dataset"
    problems = verify(ds, decode=False).problems
    assert any(p.startswith("meta/splits/seen.json: ") and line in p for p in problems), problems
    with pytest.raises(VtsError, match=line):
        vtsbench.load(ds).split_file("seen")
