"""Format 1.3, the samples as views of the episode store: info.json's `sample_storage` (schema,
bytes of other datasets kept, consistency), the index's view columns and their checks, the
check of every sample's frames against its episode, and the frame-row leak check."""

from __future__ import annotations

import io
import json

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from vtsbench.dataset.format.index import (
    VIEW_COLUMNS,
    extra_column_name,
    frame_rows,
    index_bytes,
    index_problems,
    index_schema,
    index_schema_of,
    read_index,
    view_problems,
)
from vtsbench.dataset.format.info import (
    EPISODES_FORMAT_VERSION,
    SAMPLE_STORAGE_EPISODES,
    VIEWS_FORMAT_VERSION,
    Counts,
    DatasetInfo,
    EpisodeCounts,
    ZarrSettings,
    consistency_problems,
    info_schema_errors,
)
from vtsbench.dataset.format.records import SampleMeta, SplitFile
from vtsbench.dataset.splits.leaks import check_split, leak_check, split_problems

H, W, T = 24, 32, 4


def metas(kind: str, n: int) -> list[SampleMeta]:
    slip = kind == "slip"
    return [SampleMeta(f"{kind[:2]}{i}", kind, i, "mug", 0, "s0", "gs", None, None, f"e[{i}]",
                       state="slip" if slip else None, direction=2 if slip else None)
            for i in range(n)]


def views_info(n_static: int = 2, n_slip: int = 3, **kw) -> DatasetInfo:
    ss = metas("static", n_static) + metas("slip", n_slip)
    base = dict(
        name="v", vtsbench_version="0.1.0", frames_per_sequence=T, resolution=(H, W),
        objects=["mug"], counts=Counts.of(ss),
        shapes={"static": {"rgb": (n_static, H, W, 3)}, "slip": {"rgb": (n_slip, T, H, W, 3)},
                "episodes": {"rgb": (20, H, W, 3)}},
        zarr=ZarrSettings({"episodes": 9}), format_version=VIEWS_FORMAT_VERSION,
        episodes=EpisodeCounts(2, 20, {"mug": 2}, {"s0": 2}, {"slip": 20}, 0),
        sample_storage=SAMPLE_STORAGE_EPISODES, dataset_sha256="ab" * 32)
    return DatasetInfo(**{**base, **kw})


def table(kind: str, n: int, episode_index=None, frame_row=None) -> pa.Table:
    views = None if frame_row is None else {"episode_index": episode_index,
                                            "frame_row": frame_row}
    return pq.read_table(io.BytesIO(index_bytes(kind, metas(kind, n), views=views)))


def test_sample_storage_written_only_when_set() -> None:
    info = views_info()
    doc = info.to_dict()
    assert doc["sample_storage"] == "episodes" and info.views
    assert info_schema_errors(doc) == [] and consistency_problems(info) == []
    assert DatasetInfo.from_dict(json.loads(info.to_json())) == info
    plain = views_info(sample_storage=None, format_version=EPISODES_FORMAT_VERSION)
    assert "sample_storage" not in plain.to_dict() and not plain.views
    assert "sample_storage" not in plain.to_json()
    bad = {**doc, "sample_storage": "zarr"}
    assert any("sample_storage" in e for e in info_schema_errors(bad))


@pytest.mark.parametrize(("change", "needle"), [
    ({"format_version": EPISODES_FORMAT_VERSION}, "needs format 1.3"),
    ({"episodes": None, "shapes": {"static": {"rgb": (2, H, W, 3)},
                                   "slip": {"rgb": (3, T, H, W, 3)}}}, "without episodes"),
    ({"zarr": ZarrSettings({"episodes": 9, "slip": 8})}, "zarr.samples_per_shard.slip"),
    ({"sample_storage": "zarr"}, "is not one of episodes"),
])
def test_sample_storage_consistency(change, needle) -> None:
    bad = consistency_problems(views_info(**change))
    assert any(needle in b for b in bad), bad


def test_view_columns_in_the_index() -> None:
    t = table("slip", 3, [0, 0, 1], [0, 2, 10])
    assert t.column_names[-2:] == list(VIEW_COLUMNS)
    assert index_schema_of(t.schema, "slip") is not None
    assert t.schema.equals(index_schema("slip", scale_known=False, views=True))
    assert index_problems(t, "slip", views_info()) == []
    assert frame_rows(t, "slip", T).tolist() == [[0, 1, 2, 3], [2, 3, 4, 5], [10, 11, 12, 13]]
    assert frame_rows(t, "slip", T, np.array([3, 0])).tolist() == [[3, 0], [5, 2], [13, 10]]
    s = table("static", 2, [1, 1], [12, 19])
    assert frame_rows(s, "static", T).tolist() == [[12], [19]]
    assert extra_column_name("frame_row") == "meta_frame_row"
    with pytest.raises(ValueError, match="views"):
        index_bytes("slip", metas("slip", 2), views={"frame_row": [0, 1]})


def test_view_columns_present_exactly_with_sample_storage() -> None:
    plain = table("slip", 3)
    bad = index_problems(plain, "slip", views_info())
    assert bad and "no episode_index or frame_row column" in bad[0]
    views = table("slip", 3, [0, 0, 1], [0, 2, 10])
    info12 = views_info(sample_storage=None, format_version=EPISODES_FORMAT_VERSION)
    bad = index_problems(views, "slip", info12)
    assert bad and "a episode_index column" in bad[0] and "no sample_storage" in bad[0]
    neg = table("slip", 3, [0, -1, 1], [0, 2, -5])
    bad = index_problems(neg, "slip", views_info())
    assert any("episode_index is negative in 1 row(s) (first: sl1" in b for b in bad), bad
    assert any("frame_row is negative in 1 row(s) (first: sl2" in b for b in bad), bad
    nulls = neg.set_column(neg.column_names.index("frame_row"),
                           pa.field("frame_row", pa.int64()), pa.array([0, None, 3], pa.int64()))
    assert index_schema_of(nulls.schema, "slip") is not None
    assert any("frame_row is null" in b for b in index_problems(nulls, "slip", views_info()))


def test_read_index_checks_the_view_columns(tmp_path) -> None:
    p = tmp_path / "slip.parquet"
    p.write_bytes(index_bytes("slip", metas("slip", 3),
                              views={"episode_index": [0, 0, 1], "frame_row": [0, 2, 10]}))
    assert read_index(p, "slip", views_info()).num_rows == 3
    from vtsbench.errors import VtsError

    with pytest.raises(VtsError, match="no sample_storage") as e:
        read_index(p, "slip", views_info(sample_storage=None,
                                         format_version=EPISODES_FORMAT_VERSION))
    assert "\n" not in str(e.value)


def test_frames_inside_their_episode() -> None:
    starts, lengths = np.array([0, 10]), np.array([10, 10])
    ok = table("slip", 3, [0, 0, 1], [0, 6, 16])
    assert view_problems(ok, "slip", T, starts, lengths) == []
    bad = table("slip", 4, [0, 0, 1, 2], [7, 8, 9, 0])
    out = view_problems(bad, "slip", T, starts, lengths)
    assert len(out) == 2, out
    assert out[0].startswith("episode_index is no episode of index/episodes.parquet (2 "
                             "episodes) in 1 row(s) (first: sl3 (2))")
    assert out[1].startswith("frame rows outside the sample's episode in 3 row(s) (first: sl0 "
                             "(rows 7..10, episode 0 holds 0..9)")
    static = table("static", 2, [0, 1], [9, 9])
    out = view_problems(static, "static", T, starts, lengths)
    assert out == ["frame row outside the sample's episode in 1 row(s) (first: st1 (row 9, "
                   "episode 1 holds 10..19))"]
    assert view_problems(table("slip", 2), "slip", T, starts, lengths) == []


def test_frame_rows_shared_by_two_parts_leak() -> None:
    t = table("slip", 4, [0, 0, 0, 1], [0, 2, 5, 10])
    frames = frame_rows(t, "slip", T)
    split = SplitFile("s", "slip", "d", 0, {"train": ["sl0", "sl3"], "test": ["sl1"],
                                            "val": ["sl2"]})
    tables = {"slip": t, "static": table("static", 0, [], [])}
    assert check_split(split, tables).leaks == []  # ids apart: no leak without the frames
    leaks = check_split(split, tables, frames).leaks
    assert leaks == [
        "samples 'sl0' (train) and 'sl1' (test) share frame row 2 and 1 more of the episode "
        "store (overlapping views of one take in train and test)",
        "samples 'sl2' (val) and 'sl1' (test) share frame row 5 of the episode store "
        "(overlapping views of one take in val and test)"]
    ok = SplitFile("s", "slip", "d", 0, {"train": ["sl0", "sl1"], "test": ["sl2", "sl3"]})
    assert check_split(ok, tables, frames).leaks == [  # sl1 (2..5) and sl2 (5..8) share 5
        "samples 'sl1' (train) and 'sl2' (test) share frame row 5 of the episode store "
        "(overlapping views of one take in train and test)"]
    apart = SplitFile("s", "slip", "d", 0, {"train": ["sl0", "sl1"], "test": ["sl3"]})
    assert check_split(apart, tables, frames).leaks == []
    assert leak_check(split, metas("slip", 4), frames)[0].startswith("s: samples 'sl0' (train)")
    assert leak_check(split, metas("slip", 4)) == []
    # the loader's and verify's check takes the frame rows from the index, as info.json says
    _, leaks = split_problems(split, "s", views_info(n_slip=4), tables)
    assert len(leaks) == 2 and "share frame row 2" in leaks[0]
    plain = views_info(n_slip=4, sample_storage=None, format_version=EPISODES_FORMAT_VERSION)
    assert split_problems(split, "s", plain, tables)[1] == []
