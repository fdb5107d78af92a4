"""Submission reading and validation: every malformed class gets its own message."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from vtsbench.errors import VtsError
from vtsbench.evaluation.submission import (
    Truth,
    load_submission,
    parse_pred,
    schema_errors,
    validate,
)
from vtsbench.labels import DIRECTION_NAMES, STATES

SHA = "ab" * 32


def fake_truth() -> Truth:
    """Six slip samples: three slips (directions 0, 7, 4), a press and two statics."""
    state = np.array([2, 2, 2, 1, 0, 0])
    direction = np.array([0, 7, 4, -1, -1, -1])
    return Truth("toy", "1.0.0", SHA, "seen", "test", "slip", [f"s{i}" for i in range(6)],
                 ["a", "a", "b", "b", "c", "c"], {"state": state, "direction": direction},
                 {"state": STATES, "direction": DIRECTION_NAMES})


def good_rows() -> list[dict]:
    t = fake_truth()
    rows = [{"sample_id": s, "task": "state", "pred": int(k)}
            for s, k in zip(t.ids, t.labels["state"], strict=True)]
    rows += [{"sample_id": s, "task": "direction", "pred": int(max(k, 0))}
             for s, k in zip(t.ids, t.labels["direction"], strict=True)]
    return rows


def write(tmp: Path, rows: list[dict], meta: dict | None = None, name: str = "sub.csv",
          header: str = "sample_id,task,pred") -> Path:
    path = tmp / name
    if name.endswith(".parquet"):
        pq.write_table(pa.Table.from_pylist(rows), path)
    else:
        cols = header.split(",")
        lines = [header] + [",".join(str(r.get(c, "")) for c in cols) for r in rows]
        path.write_text("\n".join(lines) + "\n")
    m = {"method": "toy net", "dataset_version": "1.0.0", "seeds": [0]} if meta is None else meta
    (tmp / (path.stem + ".meta.json")).write_text(json.dumps(m))
    return path


def problems(tmp: Path, rows: list[dict], **kw) -> str:
    path = write(tmp, rows, **kw)
    with pytest.raises(VtsError) as e:
        load_submission(path, fake_truth())
    text = str(e.value)
    assert text.startswith(str(path)) and "\n" not in text
    return text


def test_good_csv_and_parquet(tmp_path: Path) -> None:
    for name in ("sub.csv", "sub.parquet"):
        sub = load_submission(write(tmp_path, good_rows(), name=name), fake_truth())
        assert sub.seeds == [0]
        np.testing.assert_array_equal(sub.preds["state"][0], [2, 2, 2, 1, 0, 0])
        assert sub.meta["method"] == "toy net"


def test_names_and_indices() -> None:
    assert parse_pred("slip", STATES) == (2, None)
    assert parse_pred("Down-Right", DIRECTION_NAMES) == (7, None)
    assert parse_pred(" 3 ", DIRECTION_NAMES) == (3, None)
    assert parse_pred(2.0, STATES) == (2, None)
    assert parse_pred(float("nan"), STATES)[1] == "NaN or empty values"


def test_missing_ids(tmp_path: Path) -> None:
    rows = [r for r in good_rows() if r["sample_id"] != "s1"]
    text = problems(tmp_path, rows)
    # s1 misses state and direction (a true slip); a missing direction of a non-slip is fine
    assert "missing ids: 2 (first: s1 (state, seed 0), s1 (direction, seed 0))" in text
    rows = [r for r in good_rows() if not (r["sample_id"] == "s4" and r["task"] == "direction")]
    load_submission(write(tmp_path, rows), fake_truth())


def test_duplicates(tmp_path: Path) -> None:
    text = problems(tmp_path, [*good_rows(), good_rows()[0]])
    assert "duplicate rows (same sample_id, task and seed): 1 (first: s0 state)" in text


def test_ids_not_in_split(tmp_path: Path) -> None:
    text = problems(tmp_path, [*good_rows(), {"sample_id": "zz", "task": "state", "pred": 0}])
    assert "ids not in split seen/test: 1 (first: zz)" in text


def test_unknown_task(tmp_path: Path) -> None:
    text = problems(tmp_path, [*good_rows(), {"sample_id": "s0", "task": "object", "pred": 0},
                               {"sample_id": "s0", "task": "speed", "pred": 0}])
    assert "unknown tasks (a slip split scores state, direction): 2 (first: object, speed)" in text


def test_unknown_label(tmp_path: Path) -> None:
    rows = good_rows()
    rows[0]["pred"] = "sliding"
    assert "unknown labels: 1 (first: s0 state 'sliding')" in problems(tmp_path, rows)


def test_out_of_range(tmp_path: Path) -> None:
    rows = good_rows()
    rows[7]["pred"] = 8
    rows[0]["pred"] = -1
    text = problems(tmp_path, rows)
    assert "out-of-range class indices: 2 (first: s0 state '-1', s1 direction '8')" in text


def test_nan(tmp_path: Path) -> None:
    rows = good_rows()
    rows[0]["pred"] = "nan"
    rows[1]["pred"] = ""
    assert "NaN or empty values: 2" in problems(tmp_path, rows)
    rows = good_rows()
    rows[0]["score_0"] = float("nan")
    text = problems(tmp_path, rows, name="sub.parquet")
    assert "NaN or empty values: 1 (first: s0 state score_0)" in text


def test_empty_file(tmp_path: Path) -> None:
    assert "empty file (no prediction rows)" in problems(tmp_path, [])
    path = write(tmp_path, [])
    path.write_text("")
    with pytest.raises(VtsError, match="empty file"):
        load_submission(path, fake_truth())


def test_missing_columns(tmp_path: Path) -> None:
    text = problems(tmp_path, good_rows(), header="sample_id,task")
    assert "missing columns: 1 (first: pred)" in text


def test_wrong_dataset_version_and_checksum(tmp_path: Path) -> None:
    text = problems(tmp_path, good_rows(), meta={"method": "m", "dataset_version": "2.0.0",
                                                 "dataset_sha256": "cd" * 32})
    assert "wrong dataset version: 1 (first: submission 2.0.0, dataset 1.0.0)" in text
    assert "wrong dataset checksum: 1 (first: submission cdcdcdcdcdcd, dataset abababababab)" \
        in text


def test_metadata(tmp_path: Path) -> None:
    text = problems(tmp_path, good_rows(), meta={"dataset_version": "1.0.0"})
    assert "invalid metadata (sub.meta.json)" in text and "'method' is a required" in text
    path = write(tmp_path, good_rows())
    (tmp_path / "sub.meta.json").unlink()
    with pytest.raises(VtsError, match=r"1 problem.*metadata file not found"):
        load_submission(path, fake_truth())
    (tmp_path / "sub.meta.json").write_text("{not json")
    with pytest.raises(VtsError, match=r"1 problem.*sub\.meta\.json"):
        load_submission(path, fake_truth())


def test_missing_metadata_is_listed_with_the_row_problems(tmp_path: Path) -> None:
    """Every class at once, as documented: a missing metadata file, an unknown label, an id
    not in the split, missing rows and an invalid seed, in one line."""
    rows = [{**r, "seed": 0} for r in good_rows()[2:]]  # s0, s1 state missing
    rows[0]["pred"] = "wobble"  # unknown label: s2 state
    rows.append({"sample_id": "zz", "task": "state", "pred": 1, "seed": 0})  # not in split
    rows.append({"sample_id": "s3", "task": "direction", "pred": 1, "seed": "x"})  # bad seed
    path = write(tmp_path, rows, header="sample_id,task,pred,seed")
    (tmp_path / "sub.meta.json").unlink()
    with pytest.raises(VtsError) as e:
        load_submission(path, fake_truth())
    text = str(e.value)
    assert "\n" not in text and text.startswith(f"{path}: 5 problem(s): ")
    for cls in ("metadata file not found", "unknown labels: 1 (first: s2 state 'wobble')",
                "ids not in split seen/test: 1 (first: zz)", "invalid seeds",
                "missing ids: 3 (first: s0 (state, seed 0), s1 (state, seed 0), "
                "s2 (state, seed 0))"):
        assert cls in text, cls


def test_an_unreadable_submission_is_listed_with_the_metadata(tmp_path: Path) -> None:
    path = tmp_path / "sub.parquet"
    path.write_bytes(b"PAR1 not really")
    with pytest.raises(VtsError) as e:
        load_submission(path, fake_truth())
    text = str(e.value)
    assert "2 problem(s)" in text and "metadata file not found" in text
    assert "not a readable parquet file" in text


def test_every_problem_listed_at_once(tmp_path: Path) -> None:
    rows = [*good_rows()[1:], good_rows()[1], {"sample_id": "zz", "task": "state", "pred": 9}]
    sub, probs = validate(write(tmp_path, rows), fake_truth())
    assert sub is None and len(probs) == 3  # out of range, duplicate, missing


def test_seeds(tmp_path: Path) -> None:
    rows = [{**r, "seed": s} for s in (0, 1) for r in good_rows()]
    sub = load_submission(write(tmp_path, rows, header="sample_id,task,pred,seed"), fake_truth())
    assert sub.seeds == [0, 1]
    rows[0]["seed"] = "x"
    assert "invalid seeds" in problems(tmp_path, rows, header="sample_id,task,pred,seed")


def test_row_schema() -> None:
    assert schema_errors({"sample_id": "a", "task": "state", "pred": 1, "score_0": 0.5},
                         "row") == []
    assert schema_errors({"sample_id": "a", "task": "speed", "pred": 1}, "row")
    assert schema_errors({"method": "m", "dataset_version": "1.0.0"}, "metadata") == []
