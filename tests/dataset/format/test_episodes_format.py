"""The episode records mirror schemas/episode.schema.json and schemas/episode_frame.schema.json;
info.json's episode counts (format 1.2) mirror their $defs and leave other datasets' bytes
alone; the parquet schemas, dropped frames and the checks of the two tables."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from tests.fixtures.episodes import takes, write_takes
from vtsbench.dataset.format.episodes import (
    EPISODE_COLUMNS,
    FRAME_COLUMNS,
    EpisodeRecord,
    FrameRecord,
    dropped_frames,
    episode_schema,
    episode_schema_errors,
    episodes_arrow_schema,
    episodes_problems,
    episodes_table,
    extra_name_problem,
    frames_arrow_schema,
    read_table,
)
from vtsbench.dataset.format.info import (
    EPISODES_FORMAT_VERSION,
    EpisodeCounts,
    consistency_problems,
    load_info,
)
from vtsbench.dataset.format.records import schema, schema_errors
from vtsbench.errors import VtsError


def _fields(cls: type) -> set[str]:
    return {f.name for f in dataclasses.fields(cls)}


@pytest.mark.parametrize(("cls", "name", "rest"), [
    (EpisodeRecord, "episode", "meta"), (FrameRecord, "episode_frame", "extra")])
def test_records_mirror_their_schema(cls, name, rest) -> None:
    sch = episode_schema(name)
    assert _fields(cls) - {rest} == set(sch["properties"]) == set(sch["required"])
    cols = EPISODE_COLUMNS if cls is EpisodeRecord else FRAME_COLUMNS
    assert tuple(f.name for f in dataclasses.fields(cls) if f.name != rest) == cols


def test_episode_counts_mirror_info_schema() -> None:
    assert _fields(EpisodeCounts) == set(schema("dataset_info")["$defs"]["episode_counts"]
                                         ["properties"])


EPISODE = EpisodeRecord(3, "take-3", "mug", "s0", "gelsight-mini", 25.0, 40, 12, 0.48, 1,
                        0.2, "ab" * 32, {"trial": "3", "operator": None})
FRAME = FrameRecord(3, 7, 0.28, 2, 5, {"force_n": 0.5, "ok": True, "marker": "m1",
                                       "count": 4, "note": None})


@pytest.mark.parametrize(("rec", "name"), [(EPISODE, "episode"), (FRAME, "episode_frame")])
def test_records_round_trip_through_their_schema(rec, name) -> None:
    doc = json.loads(json.dumps(rec.to_dict()))
    assert episode_schema_errors(doc, name) == []
    assert type(rec).from_dict(doc) == rec


@pytest.mark.parametrize(("name", "change", "where"), [
    ("episode", {"length": 0}, "length"), ("episode", {"fps": 0}, "fps"),
    ("episode", {"episode_id": ""}, "episode_id"),
    ("episode", {"calibration_sha256": "xyz"}, "calibration_sha256"),
    ("episode", {"trial": 3}, "trial"), ("episode", {"Bad": "x"}, "(top level)"),
    ("episode_frame", {"timestamp": -1.0}, "timestamp"),
    ("episode_frame", {"state": 3}, "state"), ("episode_frame", {"direction": 8}, "direction"),
    ("episode_frame", {"frame_index": 1.0}, "frame_index"),
    ("episode_frame", {"force_n": [1]}, "force_n"),
])
def test_schemas_refuse_bad_rows(name, change, where) -> None:
    doc = {**(EPISODE if name == "episode" else FRAME).to_dict(), **change}
    errs = episode_schema_errors(doc, name)
    assert errs and errs[0].startswith(where), errs


def test_parquet_schemas_hold_the_fixed_columns_first() -> None:
    assert episodes_arrow_schema(["z", "a"]).names == [*EPISODE_COLUMNS, "a", "z"]
    schema_ = frames_arrow_schema({"b": "bool", "a": "float"})
    assert schema_.names == [*FRAME_COLUMNS, "a", "b"]
    assert str(schema_.field("state").type) == "int8" and schema_.field("state").nullable
    assert not schema_.field("timestamp").nullable
    table = episodes_table([EPISODE])
    assert table.column("trial").to_pylist() == ["3"]
    assert extra_name_problem("rgb") and extra_name_problem("Force") and not \
        extra_name_problem("force_n")


def test_dropped_frames() -> None:
    ts = np.array([0, 1, 2, 3.6, 4.6, 8.6, 9.6]) / 25  # gaps of 1.6 and 4 periods
    assert dropped_frames(ts, 25.0) == (1 + 3, 4)
    assert dropped_frames(np.arange(10) / 25 * 1.45, 25.0) == (0, -1)  # jitter under 1.5


def test_info_of_format_1_2_round_trips(tmp_path: Path) -> None:
    out = write_takes(tmp_path / "ds", takes()[:2])
    doc = json.loads((out / "meta" / "info.json").read_text())
    assert doc["format_version"] == EPISODES_FORMAT_VERSION == "1.2"
    assert schema_errors(doc, "dataset_info") == []
    assert list(doc)[-2:] == ["episodes", "info_sha256"]
    info = load_info(out)
    assert info.episodes == EpisodeCounts(2, 22, {"box": 1, "mug": 1}, {"s0": 1, "s1": 1},
                                          {"press": 4, "slip": 14, "static": 4}, 0)
    again = dataclasses.replace(info)
    assert again.to_json() == (out / "meta" / "info.json").read_text()
    assert consistency_problems(dataclasses.replace(info, format_version="1.1")) == [
        "episodes need format 1.2 or later, info.json says 1.1"]
    assert "contradicts shapes.episodes" in consistency_problems(
        dataclasses.replace(info, episodes=None))[0]


def test_a_dataset_without_episodes_keeps_its_info_bytes(vts_dataset: Path) -> None:
    text = (vts_dataset / "meta" / "info.json").read_text()
    info = load_info(vts_dataset)
    assert info.episodes is None and info.format_version == "1.1"
    assert info.to_json() == text and '"episodes"' not in text


def test_table_checks_name_what_is_wrong(tmp_path: Path) -> None:
    import pyarrow as pa

    out = write_takes(tmp_path / "ds", takes()[:2])
    info = load_info(out)
    ep, fr = read_table(out, "episodes"), read_table(out, "frames")
    assert episodes_problems(ep, fr, info) == []

    def with_col(t, name, values):
        i = t.schema.get_field_index(name)
        return t.set_column(i, t.schema.field(i), pa.array(values, t.schema.field(i).type))

    cases = [
        (with_col(ep, "frame_start", [0, 12]), fr, "frame_start does not follow"),
        (with_col(ep, "episode_id", ["a", "a"]), fr, "appear more than once"),
        (with_col(ep, "object", ["mug", "pan"]), fr, "object not in info.json objects"),
        (with_col(ep, "dropped_frames", [0, 2]), fr, "dropped_frames 2 contradicts"),
        (with_col(ep, "slip_onset_s", [9.0, None]), fr, "slip_onset_s 9.0 outside the take"),
        (ep, with_col(fr, "direction", [None] * 13 + [9] + [None] * 8), "direction outside"),
        (ep, with_col(fr, "direction", [1] + [None] * 21), "state is not slip"),
        (ep, with_col(fr, "frame_index", list(range(13)) + list(range(1, 10))),
         "rows out of place"),
        (ep, fr.slice(0, 20), "episodes hold 22 frames, index/frames.parquet 20 rows"),
    ]
    for e, f, want in cases:
        bad = episodes_problems(e, f, info)
        assert bad and want in bad[0], (want, bad)
    (out / "index" / "frames.parquet").write_bytes(b"not parquet")
    with pytest.raises(VtsError, match="not a readable parquet file"):
        read_table(out, "frames")
