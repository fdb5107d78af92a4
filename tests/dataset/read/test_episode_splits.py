"""ds.episodes.split(name, part): the episodes of one part of a split of episodes, whose
windows hold only those episodes; leaks refused at load as for the other kinds; and
windows.to_torch, whose batches (one windows.read) equal its items one by one."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

import vtsbench
from tests.fixtures.damage import edit_json, rehash
from tests.fixtures.episodes import SIZE, takes, write_takes
from vtsbench.dataset.format.layout import split_path
from vtsbench.errors import VtsError

LENGTHS = (13, 9, 20, 6)


@pytest.fixture(scope="module")
def eps_ds(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four takes of 13, 9, 20 and 6 frames (rgb, depth, contact)."""
    return write_takes(tmp_path_factory.mktemp("episodes") / "ds", takes(depth=True))


def _windows(n: int, length: int, stride: int) -> int:
    return 0 if n < length else (n - length) // stride + 1


@pytest.mark.parametrize("name", ["unseen_objects", "unseen_sessions"])
def test_split_windows_count_and_stay_inside_the_part(eps_ds: Path, name: str) -> None:
    ds = vtsbench.load(eps_ds)
    total = 0
    for part in ds.parts(name):
        eps = ds.episodes.split(name, part)
        ids = set(ds.split_file(name).parts[part])
        assert set(eps.ids) == ids
        wins = eps.windows(length=4, stride=3)
        lengths = [LENGTHS[int(e.removeprefix("episode-"))] for e in ids]
        assert len(wins) == sum(_windows(n, 4, 3) for n in lengths)
        got = {ds.episodes[int(p)]["episode_id"] for p in wins.episode_index.tolist()}
        assert got <= ids
        total += len(wins)
    assert total == len(ds.episodes.windows(length=4, stride=3))


def test_split_of_a_filtered_view_and_errors(eps_ds: Path) -> None:
    ds = vtsbench.load(eps_ds)
    mugs = ds.episodes.where(object="mug").split("unseen_sessions", "train")
    train = set(ds.split_file("unseen_sessions").parts["train"])
    assert mugs.ids == sorted(set(ds.episodes.where(object="mug").ids) & train)
    assert len(mugs) == 1  # the mug takes are of sessions s0 and s1: one in train
    with pytest.raises(VtsError, match="has no part 'fold9'"):
        ds.episodes.split("unseen_objects", "fold9")
    with pytest.raises(VtsError, match="unknown split"):
        ds.episodes.split("nope", "train")
    with pytest.raises(VtsError, match=r"ds\.episodes\.split"):
        ds.split("unseen_objects", "train")


def test_leaky_episode_split_refused_at_load(eps_ds: Path, tmp_path: Path) -> None:
    out = tmp_path / "leaky"
    shutil.copytree(eps_ds, out)
    path = out / split_path("unseen_objects")

    def leak(doc: dict) -> None:  # one of the two mug takes (0 and 3) moved to test
        assert "episode-000000" in doc["parts"]["train"], doc["parts"]
        doc["parts"]["train"].remove("episode-000000")
        doc["parts"]["test"] = sorted([*doc["parts"]["test"], "episode-000000"])

    def count(doc: dict) -> None:
        doc["counts"]["splits"]["unseen_objects"]["train"] -= 1
        doc["counts"]["splits"]["unseen_objects"]["test"] += 1

    edit_json(path, leak)
    rehash(out, count)
    ds = vtsbench.load(out)
    with pytest.raises(VtsError, match="leak: object 'mug' in both train and test"):
        ds.episodes.split("unseen_objects", "test")
    ok = vtsbench.load(out, allow_leaks=True).episodes.split("unseen_objects", "test")
    assert len(ok) == len(vtsbench.load(eps_ds).episodes.split("unseen_objects", "test")) + 1


def test_to_torch_batch_equals_items(eps_ds: Path) -> None:
    torch = pytest.importorskip("torch")
    ds = vtsbench.load(eps_ds)
    wins = ds.episodes.split("unseen_sessions", "train").windows(length=5, stride=2, pad="edge")
    tw = wins.to_torch(modality="rgbd", targets=("contact",))
    items = [3, 0, len(tw) - 1, 3]
    calls = []
    read = wins.read
    tw.windows.read = lambda *a, **k: calls.append(a) or read(*a, **k)  # type: ignore[method-assign]
    batch = tw.__getitems__(items)
    assert len(calls) == 1  # the whole batch in one read
    del tw.windows.read
    for k, (x, t) in zip(items, batch, strict=True):
        x1, t1 = tw[k]
        assert x["rgb"].dtype == torch.uint8 and x["rgb"].shape == (5, 3, *SIZE)
        assert x["depth"].shape == (5, 1, *SIZE) and x["depth"].dtype == torch.float32
        assert torch.equal(x["rgb"], x1["rgb"]) and torch.equal(x["depth"], x1["depth"])
        assert t["episode_id"] == t1["episode_id"] == wins.read([k])["episode_id"][0]
        for name in ("frame_index", "timestamps", "state", "direction", "pad_mask", "contact"):
            assert torch.equal(t[name], t1[name]), name
        raw = wins[k]
        assert np.array_equal(x["rgb"].permute(0, 2, 3, 1).numpy(), raw["rgb"])
        assert np.array_equal(t["pad_mask"].numpy(), raw["pad_mask"])
    small = wins.to_torch(size=(12, 16), dtype="float32")
    x, _ = small[0]
    assert x.shape == (5, 3, 12, 16) and x.dtype == torch.float32 and float(x.max()) <= 1.0
    loader = torch.utils.data.DataLoader(wins.to_torch(), batch_size=4, collate_fn=list)
    assert sum(len(b) for b in loader) == len(wins)
