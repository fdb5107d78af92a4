"""Typed results and task declarations: metrics.json read back as an EvalResult gives the same
bytes, committed leaderboard entries read back unchanged, and every task, metric and
leaderboard column named in evaluation/tasks.py exists in metrics.schema.json."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.fixtures.data import ROOT
from tests.fixtures.submissions import slip_split, write_submission
from vtsbench.cli import app
from vtsbench.dataset.format.records import SCHEMA_DIR
from vtsbench.errors import VtsError
from vtsbench.evaluation.report import (
    direction_line,
    evaluate,
    evaluate_submission,
    summary_rows,
)
from vtsbench.evaluation.result import (
    EvalResult,
    read_metrics,
    tasks_from_dict,
    tasks_to_dict,
)
from vtsbench.evaluation.tasks import (
    BOARDS,
    DIRECTION,
    STATE,
    TASKS,
    board_columns,
    headline_column,
    kind_of,
    task_columns,
    tasks_of,
)
from vtsbench.labels import N_DIRECTIONS

BOARDS_DIR = ROOT / "leaderboards"
SCHEMA = json.loads((SCHEMA_DIR / "metrics.schema.json").read_text())
RUN_FIELDS = set(SCHEMA["$defs"]["run"]["properties"])


def test_metrics_json_reads_back_to_the_same_bytes(vts_dataset: Path, tmp_path: Path) -> None:
    split, part = slip_split(vts_dataset)
    sub = write_submission(vts_dataset, tmp_path / "sub", split, part, wrong=2)
    result, _, _ = evaluate_submission(sub, vts_dataset, split, part, out=tmp_path / "ev",
                                       figures=False)
    text = (tmp_path / "ev" / "metrics.json").read_text()
    assert result.to_json() == text
    assert read_metrics(tmp_path / "ev" / "metrics.json") == result
    assert json.dumps(EvalResult.from_dict(json.loads(text)).to_dict()) == \
        json.dumps(json.loads(text))  # keys in the same order
    doc, _, _ = evaluate(sub, vts_dataset, split, part)
    assert doc == result.to_dict() and summary_rows(doc) == summary_rows(result)
    d = result.tasks["direction"]
    assert d.first.value("within_one_bin") == d.first.direction.within_one_bin
    assert result.tasks["state"].first.value("within_one_bin") is None
    assert d.mean("not a metric") is None and d.first.value("not a metric") is None


def test_eval_prints_the_direction_line(vts_dataset: Path, tmp_path: Path) -> None:
    split, part = slip_split(vts_dataset)
    sub = write_submission(vts_dataset, tmp_path / "sub", split, part, wrong=1)
    res = CliRunner().invoke(app, ["eval", str(sub), "--dataset", str(vts_dataset),
                                   "--split", split, "--part", part])
    assert res.exit_code == 0, res.output
    result, _, _ = evaluate_submission(sub, vts_dataset, split, part)
    line = direction_line(result)
    assert line is not None and line in res.output


def test_a_malformed_metrics_file_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "metrics.json"
    path.write_text('{"metric_version": "1.0"}')
    with pytest.raises(VtsError) as e:
        read_metrics(path)
    assert str(e.value).startswith(f"{path}: not a metrics.json") and "\n" not in str(e.value)


ENTRIES = sorted(BOARDS_DIR.glob("*/*/*.json"))


@pytest.mark.skipif(not ENTRIES, reason="no published entries")
def test_committed_entries_read_back_unchanged() -> None:
    for path in ENTRIES:
        metrics = json.loads(path.read_text())["metrics"]
        assert json.dumps(tasks_to_dict(tasks_from_dict(metrics))) == json.dumps(metrics), path


def test_tasks_are_declared_once_and_match_the_schema() -> None:
    assert set(TASKS) == set(SCHEMA["$defs"]["tasks"]["propertyNames"]["enum"])
    assert tasks_of("slip") == (STATE, DIRECTION) and [t.name for t in tasks_of("static")] == \
        ["object"]
    assert kind_of(["direction"]) == "slip" and kind_of([]) == "static"
    assert len(DIRECTION.classes) == len(DIRECTION.axis_labels) == N_DIRECTIONS
    for task in TASKS.values():
        assert task.headline in task.summary and set(task.summary) <= RUN_FIELDS, task.name
        assert headline_column(task).task == task.name
        assert board_columns(task), task.name
        for col in task_columns(task):
            assert col.metric in RUN_FIELDS, (task.name, col)
    for kind, board in BOARDS.items():
        assert board.rank in {t.name for t in tasks_of(kind)}
        for col in board.columns:
            assert TASKS[col.task].kind == kind and col.metric in RUN_FIELDS, col
            if col.show in ("pct", "deg", "mean_std"):  # means over seeds: summarised metrics
                assert col.metric in TASKS[col.task].summary, col
    assert [c.header for c in task_columns(DIRECTION)][-2:] == \
        ["adjacent share of errors %", "worst object %"]
