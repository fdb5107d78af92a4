"""Seeded fuzzing of the files users give vtsbench: manifests, submissions (CSV and metadata),
calibration files and dataset metadata. Every mutation makes the file invalid (a hostile value
where a number is expected, a truncation, a repeated column, an over-long field, bad UTF-8),
and every run must end cleanly: exit 1 or 2, the file named, no traceback. Bounded in time
(FUZZ_SECONDS per file kind; set VTSBENCH_FUZZ_SECONDS to fuzz longer), so the suite stays
fast; the count is printed (pytest -s)."""

from __future__ import annotations

import json
import os
import random
import shutil
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.fixtures.hostile import HOSTILE, TYPED, mutate_json
from vtsbench.cli import app

FUZZ_SECONDS = float(os.environ.get("VTSBENCH_FUZZ_SECONDS", "2"))


def mutate_csv(data: bytes, rng: random.Random) -> bytes:
    lines = data.decode().splitlines()
    head, body = lines[0].split(","), lines[1:]
    pick = rng.randrange(5)
    if pick == 0:  # a repeated column name
        return (",".join([*head, rng.choice(head)]) + "\n" + "\n".join(body)).encode()
    if pick == 1:  # a field over the csv module's 128 KiB limit
        return data + b"x,state," + b"y" * 140_000 + b"\n"
    if pick == 2:  # invalid UTF-8
        return data[:len(data) // 2] + b"\xff" + data[len(data) // 2:]
    if pick == 3:  # a hostile prediction
        row = rng.randrange(len(body))
        cells = body[row].split(",")
        cells[2] = rng.choice(["nan", "inf", "-1", "99", "[/x]", "1e999", "9" * 5000])
        body[row] = ",".join(cells)
        return ("\n".join([lines[0], *body]) + "\n").encode()
    return b"sample_id,task\n" + data  # a second header row, columns shifted


def clean_exit(res, name: str) -> bool:
    """Exit 1 or 2, no traceback, the file named in the output."""
    return (res.exit_code in (1, 2) and isinstance(res.exception, SystemExit)
            and "Traceback" not in res.output and name in res.output)


def fuzz(target: Path, mutate: Callable[[bytes, random.Random], bytes], args: list[str],
         seed: int) -> tuple[int, list[str]]:
    """Mutate target repeatedly for FUZZ_SECONDS, running the command each time."""
    rng = random.Random(seed)
    orig = target.read_bytes()
    runner = CliRunner()
    n, bad = 0, []
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < FUZZ_SECONDS or n < 20:
        data = mutate(orig, rng)
        target.write_bytes(data)
        res = runner.invoke(app, args)
        n += 1
        if not clean_exit(res, target.name):
            bad.append(f"{target.name} #{n}: exit {res.exit_code}, {res.exception!r}, "
                       f"{res.output[-300:]!r}")
    target.write_bytes(orig)
    return n, bad


@pytest.fixture
def work(built: Path, sim_recordings: Path, tmp_path: Path) -> dict[str, Path]:
    ds = Path(shutil.copytree(built, tmp_path / "ds"))
    rec = Path(shutil.copytree(sim_recordings, tmp_path / "rec"))
    import vtsbench

    view = vtsbench.load(ds).split("seen", "test")
    ids = [view[i]["sample_id"] for i in range(len(view))]
    sub = tmp_path / "sub.csv"
    sub.write_text("sample_id,task,pred\n" + "".join(
        f"{s},state,slip\n{s},direction,3\n" for s in ids))
    (tmp_path / "sub.meta.json").write_text(
        '{"method": "fuzz", "recipe": "none", "seeds": [0], "extra": {"score": 0.5}}\n')
    img = next((rec / "static").glob("*.png"))
    return {"ds": ds, "rec": rec, "sub": sub, "meta": tmp_path / "sub.meta.json", "img": img,
            "tmp": tmp_path}


def test_fuzz_user_files(work: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    ds, rec, tmp = work["ds"], work["rec"], work["tmp"]
    eval_args = ["eval", str(work["sub"]), "--dataset", str(ds), "--split", "seen"]
    cal = rec / "calibration.safetensors"

    def mutate_cal(data: bytes, rng: random.Random) -> bytes:
        n = int.from_bytes(data[:8], "little")
        if rng.random() < 0.3:  # truncated, or a header length past the end
            return data[:rng.randrange(0, len(data) - 1)]
        head = data[8:8 + n]
        if rng.random() < 0.5:  # the header itself
            head = mutate_json(head, rng)
        else:  # the vtsbench metadata, a JSON document held as a string in the header
            doc = json.loads(head)
            meta = doc["__metadata__"]["vtsbench"].encode()
            try:
                text = mutate_json(meta, rng).decode()
            except UnicodeDecodeError:  # bad UTF-8 cannot travel in a JSON string: truncate
                text = meta[:len(meta) // 2].decode(errors="ignore")
            doc["__metadata__"]["vtsbench"] = text
            head = json.dumps(doc).encode()
        return len(head).to_bytes(8, "little") + head + data[8 + n:]

    def mutate_own(data: bytes, rng: random.Random) -> bytes:
        return mutate_json(data, rng, HOSTILE + TYPED)

    runs = [
        ("manifest", rec / "recordings.json", mutate_json, ["check", str(rec)]),
        ("submission CSV", work["sub"], mutate_csv, eval_args),
        ("submission metadata", work["meta"], mutate_json, eval_args),
        ("calibration", cal, mutate_cal, ["depth", str(work["img"]), "--calibration", str(cal),
                                          "--out", str(tmp / "depth")]),
        ("dataset info.json", ds / "meta" / "info.json", mutate_own,
         ["verify", str(ds), "--quick"]),
        ("dataset split file", ds / "meta" / "splits" / "seen.json", mutate_own,
         ["verify", str(ds), "--quick"]),
        ("Zarr metadata", ds / "data" / "slip.zarr" / "zarr.json", mutate_own,
         ["verify", str(ds), "--quick"]),
    ]
    total, failures = 0, []
    lines = []
    for seed, (what, target, mutate, args) in enumerate(runs):
        n, bad = fuzz(target, mutate, args, seed)
        total += n
        failures += bad
        lines.append(f"{what}: {n} inputs, {n - len(bad)} clean")
    with capsys.disabled():
        print(f"\nfuzz: {total} inputs, {total - len(failures)} handled cleanly "
              f"({100 * (total - len(failures)) / total:.1f} %); " + "; ".join(lines))
    assert not failures, failures[:5]


# -- damaged datasets: every checksum recomputed, so only the validator can tell --------------

#: Values put into an index cell (cast to the column's type where they can be).
CELLS = [None, float("nan"), float("inf"), -1, 0, 42, 1e9, -500.0, "ghost", "", "slip"]


def _damage_index(ds: Path, rng: random.Random) -> str:
    import pyarrow as pa
    import pyarrow.parquet as pq

    from tests.fixtures.damage import rewrite_index

    kind = rng.choice(["static", "slip"])
    table = pq.read_table(ds / "index" / f"{kind}.parquet")
    n = len(table)
    pick = rng.random()
    if pick < 0.15:
        order = list(range(n))
        rng.shuffle(order)
        rewrite_index(ds, kind, lambda t: t.take(pa.array(order)))
        return f"{kind} rows permuted"
    if pick < 0.25:
        drop = rng.randrange(n)
        rewrite_index(ds, kind, lambda t: t.take(pa.array([i for i in range(n) if i != drop])))
        return f"{kind} row {drop} dropped"
    i = rng.randrange(table.num_columns)
    field, row, value = table.schema.field(i), rng.randrange(n), rng.choice(CELLS)
    values = table.column(i).to_pylist()
    values[row] = values[rng.randrange(n)] if rng.random() < 0.2 else value
    try:
        col = pa.array(values, field.type)
    except (pa.ArrowException, TypeError, ValueError, OverflowError):
        values[row] = None
        col = pa.array(values, field.type)
    if col.null_count and not field.nullable:  # a null where none may be: a nullable column
        field = field.with_nullable(True)
    rewrite_index(ds, kind, lambda t: t.set_column(i, field, col))
    return f"{kind} {field.name}[{row}] = {values[row]!r}"


def _damage_split(ds: Path, rng: random.Random) -> str:
    from tests.fixtures.damage import rehash

    name = rng.choice(sorted(p.stem for p in (ds / "meta" / "splits").glob("*.json")))
    path = ds / "meta" / "splits" / f"{name}.json"
    doc = json.loads(path.read_text())
    parts = sorted(doc["parts"])
    a, b = rng.choice(parts), rng.choice(parts)
    pick = rng.randrange(7)
    if pick == 0 and doc["parts"][a]:  # an id also in another part (a leak)
        doc["parts"][b] = sorted(set(doc["parts"][b]) | {rng.choice(doc["parts"][a])})
    elif pick == 1:
        doc["parts"][a] = sorted([*doc["parts"][a], rng.choice(["ghost", "static-00001",
                                                               "seq-00001"])])
        doc["parts"][a] = sorted(set(doc["parts"][a]))
    elif pick == 2 and doc["parts"][a]:
        doc["parts"][a] = doc["parts"][a][1:]
    elif pick == 3:
        doc["kind"] = "static" if doc["kind"] == "slip" else "slip"
    elif pick == 4:
        doc["disjoint"] = sorted(set(doc["disjoint"]) | {rng.choice(
            ["object", "session", "location", f"object:{b}", "session:test"])})
    elif pick == 5:
        doc["name"] = rng.choice(["seen", "other", name])
    else:
        doc["parts"][f"fold{rng.randrange(3)}"] = doc["parts"].pop(a)
    path.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
    counts = rng.random() < 0.8  # mostly counts kept in step, so the parts themselves are tried
    rehash(ds, lambda d: counts and d["counts"]["splits"].__setitem__(
        name, {p: len(v) for p, v in doc["parts"].items()}))
    return f"split {name}: change {pick}, counts {'fixed' if counts else 'kept'}"


def _damage_zarr(ds: Path, rng: random.Random) -> str:
    from tests.fixtures.damage import edit_json, rehash

    kind, name = rng.choice(["static", "slip"]), rng.choice(["rgb", "depth", "contact"])
    group = rng.random() < 0.5
    path = ds / "data" / f"{kind}.zarr" / ("zarr.json" if group else f"{name}/zarr.json")
    key = rng.choice(["shape", "chunk", "inner", "dtype", "scale", "level", "fill"])

    def change(doc: dict) -> None:
        d = doc["consolidated_metadata"]["metadata"][name] if group else doc
        if key == "shape":
            d["shape"][0] += rng.choice([-1, 1])
        elif key == "chunk":
            d["chunk_grid"]["configuration"]["chunk_shape"][0] += 1
        elif key == "inner":
            d["codecs"][0]["configuration"]["chunk_shape"][-1] //= 2
        elif key == "dtype":
            d["data_type"] = rng.choice(["uint16", "float32", "int8"])
        elif key == "scale":
            d["attributes"]["scale_factor"] = 0.002
        elif key == "level" and name != "contact":
            d["codecs"][0]["configuration"]["codecs"][1]["configuration"]["level"] = 9
        else:
            d["fill_value"] = 1 if name != "contact" else True
    edit_json(path, change)
    rehash(ds)
    return f"{path.relative_to(ds)}: {key}"


def _damage_info(ds: Path, rng: random.Random) -> str:
    from tests.fixtures.damage import rehash

    key = rng.choice(["depth_scale_mm", "frames_per_sequence", "resolution", "objects",
                      "counts", "format_version", "splits", "samples_per_shard", "arrays"])

    def edit(d: dict) -> None:
        if key == "depth_scale_mm":
            d[key] = rng.choice([0.002, 0.0005])
        elif key == "frames_per_sequence":
            d[key] += 1
        elif key == "resolution":
            d[key] = [d[key][1], d[key][0]]
        elif key == "objects":
            d[key][0] = "aaa_new" if rng.random() < 0.5 else d[key][0]
            d[key][-1] = "zzz_new"
        elif key == "counts":
            d[key]["static"]["objects"][next(iter(d[key]["static"]["objects"]))] += 1
        elif key == "format_version":
            d[key] = "1.0"
            d.pop("info_sha256")
        elif key == "splits":
            name = next(iter(d["splits"]))
            d["splits"][f"x{name}"] = d["splits"].pop(name)
            d["counts"]["splits"][f"x{name}"] = d["counts"]["splits"].pop(name)
        elif key == "samples_per_shard":
            d["zarr"]["samples_per_shard"]["static"] += 1
        else:
            for kind in d["shapes"]:
                d["shapes"][kind].pop("contact")
    rehash(ds, edit)
    return f"info.json: {key}"


def test_fuzz_damaged_datasets(built: Path, tmp_path: Path,
                               capsys: pytest.CaptureFixture[str]) -> None:
    """Seeded damage to the index, split files, zarr.json and info.json, every checksum
    recomputed: verify reports a problem exactly when the loader refuses (on load or on use),
    and neither ever raises anything but a one-line VtsError."""
    from tests.fixtures.datasets import use_dataset
    from vtsbench.dataset.tools.verify import verify
    from vtsbench.errors import VtsError

    rng = random.Random(21)
    damages = [_damage_index, _damage_split, _damage_zarr, _damage_info]
    n, refused, bad = 0, 0, []
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < FUZZ_SECONDS or n < 12:
        ds = tmp_path / f"ds{n}"
        shutil.copytree(built, ds)
        damage = damages[n % len(damages)]
        what = damage(ds, rng)
        try:
            problems = verify(ds, decode=damage is _damage_zarr).problems
            try:
                use_dataset(ds)
                refusal = None
            except VtsError as e:
                refusal = str(e)
            if bool(problems) != (refusal is not None) or "\n" in (refusal or ""):
                bad.append(f"{what}: verify {problems[:2]}, loader {refusal!r}")
            refused += refusal is not None
        except Exception as e:  # a traceback: never allowed
            bad.append(f"{what}: {type(e).__name__}: {e}")
        shutil.rmtree(ds)
        n += 1
    with capsys.disabled():
        print(f"\nfuzz damaged datasets: {n} damages in {time.perf_counter() - t0:.1f} s, "
              f"{refused} refused by both, "
              f"{n - refused - len(bad)} accepted by both, {len(bad)} disagreements")
    assert not bad, bad[:5]
