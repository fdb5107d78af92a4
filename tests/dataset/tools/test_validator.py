"""One validator for `vtsbench verify` and `vtsbench.load`: every class of damage, made with all
checksums recomputed (as a deliberate change would be), is a verify problem AND a one-line
refusal of the loader (on load, or on first use: a split, a read); leaks are refused unless
allowed explicitly; a split of a million unknown ids is refused quickly in a few lines."""

from __future__ import annotations

import json
import shutil
import time
from collections.abc import Callable
from pathlib import Path

import pyarrow as pa
import pytest
from typer.testing import CliRunner

import vtsbench
from tests.fixtures.damage import edit_json, rehash, rewrite_index, write_info_text
from tests.fixtures.datasets import use_dataset
from vtsbench.cli import app
from vtsbench.dataset.tools.verify import verify
from vtsbench.errors import VtsError


def set_column(kind: str, name: str, row: int, value: object) -> Callable[[Path], None]:
    """Damage: one value of an index column."""
    def damage(ds: Path) -> None:
        def change(t: pa.Table) -> pa.Table:
            values = t.column(name).to_pylist()
            values[row] = value
            i = t.schema.get_field_index(name)
            return t.set_column(i, t.schema.field(i), pa.array(values, t.schema.field(i).type))
        rewrite_index(ds, kind, change)
    return damage


def swap_class_idx(ds: Path) -> None:
    def change(t: pa.Table) -> pa.Table:
        v = t.column("class_idx").to_pylist()
        v[0], v[1] = v[1], v[0]
        i = t.schema.get_field_index("class_idx")
        return t.set_column(i, t.schema.field(i), pa.array(v, pa.int32()))
    rewrite_index(ds, "static", change)


def permute_rows(ds: Path) -> None:
    """Index rows in another order (each keeps its row): zarr row r is no longer position r."""
    rewrite_index(ds, "slip", lambda t: t.take(pa.array(list(range(len(t)))[::-1])))


def depth_scale(ds: Path) -> None:
    rehash(ds, lambda d: d.update(depth_scale_mm=0.002))


def duplicate_key(ds: Path) -> None:
    text = (ds / "meta" / "info.json").read_text()
    old = '"depth_scale_mm": 0.001,'
    assert old in text
    write_info_text(ds, text.replace(old, f'{old}\n "depth_scale_mm": 0.002,', 1))


def downgrade(ds: Path) -> None:
    """format_version 1.0 over arrays written by 1.1: info_sha256 dropped."""
    rehash(ds, lambda d: (d.update(format_version="1.0"), d.pop("info_sha256")))


def array_json(key: str, value: object) -> Callable[[Path], None]:
    """Damage: a field of one array's own zarr.json, the consolidated copy left as it was."""
    def damage(ds: Path) -> None:
        def change(doc: dict) -> None:
            if key == "shape":
                doc["shape"][0] = value
            else:
                doc["chunk_grid"]["configuration"]["chunk_shape"][0] = value
        edit_json(ds / "data" / "static.zarr" / "rgb" / "zarr.json", change)
        rehash(ds)
    return damage


def evil_split_name(ds: Path) -> None:
    shutil.copy(ds / "meta" / "splits" / "seen.json", ds / "meta" / "evil.json")

    def edit(d: dict) -> None:
        d["splits"]["../evil"] = d["splits"]["seen"]
        d["counts"]["splits"]["../evil"] = d["counts"]["splits"]["seen"]
    rehash(ds, edit)


def edit_split(ds: Path, name: str, change: Callable[[dict], None]) -> None:
    """Rewrite a split file with change(doc), its sha256 and part counts in info.json fixed."""
    path = ds / "meta" / "splits" / f"{name}.json"
    doc = json.loads(path.read_text())
    change(doc)
    path.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
    rehash(ds, lambda d: d["counts"]["splits"].__setitem__(
        name, {p: len(v) for p, v in doc["parts"].items()}))


def leak(ds: Path) -> None:
    """A seen object's training sample also in the unseen-objects test part."""
    def change(doc: dict) -> None:
        doc["parts"]["test"] = sorted([*doc["parts"]["test"], doc["parts"]["train"][0]])
    edit_split(ds, "unseen_objects", change)


DAMAGE = {
    "depth_scale_mm changed": depth_scale,
    "duplicate key in info.json": duplicate_key,
    "format 1.0 over 1.1 arrays": downgrade,
    "array zarr.json shape": array_json("shape", 99),
    "array zarr.json chunk shape": array_json("chunk", 2),
    "NaN mm_per_px_x": set_column("static", "mm_per_px_x", 0, float("nan")),
    "swapped class_idx": swap_class_idx,
    "permuted index rows": permute_rows,
    "unknown object": set_column("static", "object", 0, "ghost"),
    "direction 42": set_column("slip", "direction", 2, 42),
    "split named ../evil": evil_split_name,
    "contact outside the frame": lambda ds: (set_column("static", "contact_x_px", 0, -500.0)(ds),
                                             set_column("static", "contact_y_px", 0, 1e6)(ds)),
    "leaking split": leak,
    "negative press depth": set_column("static", "press_depth_mm", 1, -1.0),
    "state_idx against state": set_column("slip", "state_idx", 0, 2),
}


def test_intact_dataset_verifies_and_loads(built: Path) -> None:
    assert verify(built, decode=False).ok
    use_dataset(built)


@pytest.mark.parametrize("damage", DAMAGE.values(), ids=list(DAMAGE))
def test_verify_and_the_loader_agree(ds: Path, damage: Callable[[Path], None]) -> None:
    damage(ds)
    problems = verify(ds, decode=False).problems
    assert problems
    assert not any(p.endswith("sha256 mismatch") or "sha256 mismatch" in p for p in problems), \
        problems  # the damage is not told by a checksum
    with pytest.raises(VtsError) as e:
        use_dataset(ds)
    assert "\n" not in str(e.value)


def test_a_leak_names_the_split_file_and_can_be_allowed(ds: Path) -> None:
    leak(ds)
    d = vtsbench.load(ds)
    with pytest.raises(VtsError, match=r"unseen_objects\.json: leak: sample '.+' in both train "
                                       r"and test") as e:
        d.split("unseen_objects", "train")
    assert "allow_leaks=True" in str(e.value)
    d.split("seen", "train")  # the other splits stay usable
    allowed = vtsbench.load(ds, allow_leaks=True)
    test = allowed.split("unseen_objects", "test")
    assert set(test.ids) == set(allowed.split_file("unseen_objects").parts["test"])


def test_eval_refuses_a_leaking_split(ds: Path, tmp_path: Path) -> None:
    leak(ds)
    sub = tmp_path / "s.csv"
    sub.write_text("sample_id,task,pred\n")
    (tmp_path / "s.meta.json").write_text('{"method": "m", "recipe": "none", "seeds": [0]}')
    res = CliRunner().invoke(app, ["eval", str(sub), "--dataset", str(ds), "--split",
                                   "unseen_objects"])
    assert res.exit_code == 2 and "leak:" in res.output and "Traceback" not in res.output, \
        res.output


def test_a_split_of_a_million_unknown_ids_is_refused_quickly(ds: Path, tmp_path: Path) -> None:
    def change(doc: dict) -> None:
        doc["parts"]["test"] = [f"ghost-{i:07d}" for i in range(1_000_000)]
    edit_split(ds, "seen", change)
    runner = CliRunner()
    t0 = time.perf_counter()
    res = runner.invoke(app, ["verify", str(ds), "--quick"])
    lines = [ln for ln in res.output.splitlines() if "seen.json" in ln]
    assert res.exit_code == 1 and 1 <= len(lines) <= 3, res.output
    with pytest.raises(VtsError, match=r"seen\.json: split file of"):
        vtsbench.load(ds).split("seen", "test")
    sub = tmp_path / "s.csv"
    sub.write_text("sample_id,task,pred\n")
    (tmp_path / "s.meta.json").write_text('{"method": "m", "recipe": "none", "seeds": [0]}')
    res = runner.invoke(app, ["eval", str(sub), "--dataset", str(ds), "--split", "seen"])
    assert res.exit_code == 2 and "seen.json" in res.output, res.output
    assert time.perf_counter() - t0 < 5


def test_unknown_ids_within_the_bounds_are_one_line_per_part(ds: Path) -> None:
    """A split small enough to be read: unknown ids counted per part, a few shown."""
    def change(doc: dict) -> None:
        doc["parts"]["train"] = [f"ghost-{i}" for i in range(3)] + doc["parts"]["train"][3:]
        doc["parts"]["test"] = ["ghost-x", "static-00001"]
    edit_split(ds, "seen", change)
    problems = [p for p in verify(ds, decode=False).problems if "seen.json" in p]
    assert "meta/splits/seen.json: part train: 3 sample id(s) not in index/slip.parquet: " \
           "'ghost-0', 'ghost-1', 'ghost-2'" in problems, problems
    assert any("part test: 1 id(s) of samples of the other kind" in p for p in problems)
    with pytest.raises(VtsError, match="part train: 3 sample id"):
        vtsbench.load(ds).split("seen", "train")


@pytest.mark.parametrize("what", ["folder", "fifo"])
def test_info_or_index_that_is_no_file_is_said_so(ds: Path, what: str) -> None:
    import os

    for rel in ("meta/info.json", "index/static.parquet"):
        d = Path(shutil.copytree(ds, ds.parent / f"copy-{rel[:4]}"))
        (d / rel).unlink()
        if what == "folder":
            (d / rel).mkdir()
        else:
            os.mkfifo(d / rel)
        with pytest.raises(VtsError, match=r"a folder|a pipe") as e:
            vtsbench.load(d)
        assert "not found" not in str(e.value)
        res = CliRunner().invoke(app, ["verify", str(d), "--quick"])
        assert res.exit_code == 1 and "not found" not in res.output, res.output
        assert "a folder" in res.output or "a pipe" in res.output, res.output
        lines = [ln for ln in res.output.splitlines() if ln.startswith(f"problem {rel}")]
        assert rel == "meta/info.json" or len(lines) == 1, res.output  # never also "missing"
        assert "missing" not in res.output, res.output


def test_a_shard_linked_to_a_device_is_not_called_missing(ds: Path) -> None:
    shard = next(p for p in sorted((ds / "data" / "static.zarr" / "rgb").rglob("*"))
                 if p.is_file())
    shard.unlink()
    shard.symlink_to("/dev/zero")
    res = CliRunner().invoke(app, ["verify", str(ds), "--quick"])
    assert res.exit_code == 1 and "missing" not in res.output, res.output
    assert "not a regular file but a pipe, device or socket" in res.output, res.output


def test_duplicate_keys_are_refused_in_every_json_read(tmp_path: Path) -> None:
    from vtsbench.jsonio import loads

    assert loads('{"a": {"b": 1}, "c": [{"b": 2}, {"b": 3}]}', "x") == {
        "a": {"b": 1}, "c": [{"b": 2}, {"b": 3}]}
    with pytest.raises(VtsError, match="key 'b' appears more than once"):
        loads('{"a": [{"b": 1, "b": 2}]}', "x")
