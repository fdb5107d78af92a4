"""Bad recordings stop the build with one line naming the entry, or are skipped and reported."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.fixtures.datasets import BUILD_ARGS, SHARD_MB
from tests.fixtures.recordings import copy_recordings
from vtsbench.cli import app
from vtsbench.dataset.build import BuildOptions, build
from vtsbench.dataset.format.index import read_metas as read_index
from vtsbench.dataset.tools.verify import verify
from vtsbench.errors import VtsError


def _edit_manifest(rec: Path, entry_id: str, **source: int) -> None:
    path = rec / "recordings.json"
    doc = json.loads(path.read_text())
    for e in doc["entries"]:
        if e["id"] == entry_id:
            e["source"].update(source)
    path.write_text(json.dumps(doc, indent=1))


def _build_cli(rec: Path, out: Path, *extra: str):
    return CliRunner().invoke(app, ["build", str(rec), str(out), *BUILD_ARGS, *extra])


def test_bad_entries_stop_the_build_or_are_skipped(sim_recordings: Path, tmp_path: Path) -> None:
    rec = copy_recordings(sim_recordings, tmp_path / "rec")
    (rec / "static" / "static-00002.png").write_bytes(b"not a png")  # undecodable
    _edit_manifest(rec, "seq-00003", stop=5)  # shorter than T = 8
    for f in (rec / "sequences" / "seq-00005").iterdir():  # missing files
        f.unlink()
    out = tmp_path / "ds"
    res = _build_cli(rec, out)
    assert res.exit_code == 2
    lines = res.output.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("error: bad recording seq-00003: sequences/seq-00003: sequence "
                               "of 5 frames is shorter than --frames 8 (and 2 more bad entries)")
    assert not out.exists()

    res = _build_cli(rec, out, "--skip-bad")
    assert res.exit_code == 0, res.output
    for eid in ("static-00002", "seq-00003", "seq-00005"):
        assert f"skipped {eid}:" in res.output
    report = json.loads((out / "meta" / "build_report.json").read_text())
    skipped = {s["entry"]: s["reason"] for s in report["skipped"]}
    assert set(skipped) == {"static-00002", "seq-00003", "seq-00005"}
    assert "cannot decode image" in skipped["static-00002"]
    assert "image folder holds no images" in skipped["seq-00005"]
    ids = {m.sample_id for k in ("static", "slip")
           for m in read_index(out / "index" / f"{k}.parquet", k)}
    assert not ids & set(skipped) and len(ids) == 15 - 3
    assert verify(out).ok


def test_a_frame_found_bad_while_building(sim_recordings: Path, tmp_path: Path) -> None:
    """A middle frame `vtsbench check` does not decode: found by the shard task."""
    rec = copy_recordings(sim_recordings, tmp_path / "rec")
    (rec / "sequences" / "seq-00004" / "003.png").write_bytes(b"\x89PNG broken")
    opts = BuildOptions(shard_mb=SHARD_MB)
    with pytest.raises(VtsError) as err:
        build(rec, tmp_path / "ds", opts)
    msg = str(err.value)
    assert msg.startswith("bad recording seq-00004: sequences/seq-00004/003.png: cannot decode")
    assert "\n" not in msg
    res = build(rec, tmp_path / "ds", BuildOptions(shard_mb=SHARD_MB, skip_bad=True))
    assert list(res.skipped) == ["seq-00004"] and res.samples["slip"] == 8
    assert (res.shards_kept, res.shards_built) == (5, 5)  # slip 3 failed, then 3..7 again
    assert verify(tmp_path / "ds").ok


def test_windows_of_t_frames(sim_recordings: Path, tmp_path: Path) -> None:
    res = build(sim_recordings, tmp_path / "ds", BuildOptions(frames=3, shard_mb=1.0))
    metas = read_index(tmp_path / "ds" / "index" / "slip.parquet", "slip")
    assert res.samples["slip"] == 18 and res.frames["slip"] == 54  # 2 windows of 3 of 8 frames
    assert [m.sample_id for m in metas[:2]] == ["seq-00001-w000", "seq-00001-w001"]
    assert [m.source.rsplit("[", 1)[1] for m in metas[:2]] == ["0:3]", "3:6]"]
    assert metas[0].state == metas[1].state and metas[0].object == metas[1].object
