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
import re
import shutil
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from typer.testing import CliRunner

from vtsbench.cli import app

pytest_plugins = ["test_build_helpers"]

FUZZ_SECONDS = float(os.environ.get("VTSBENCH_FUZZ_SECONDS", "4"))
#: Values that no JSON a user gives may hold: refused by the parser wherever they stand.
HOSTILE = ["NaN", "Infinity", "-Infinity", "1e999", "-1e999", "9" * 5000,
           "[" * 50_000 + "]" * 50_000]
#: And values that are wrong only where a number is expected (free-form metadata may hold
#: them): used on the dataset's own files, every byte of which is checksummed.
TYPED = ['"[/x]"', '"[bold]x"', "{}", "true", '"\\u0000"']
NUMBER = re.compile(rb"(?<![\w.\"-])-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?(?![\w.\"])")


def mutate_json(data: bytes, rng: random.Random, values: list[str] = HOSTILE) -> bytes:
    """A hostile value in place of a number, or a truncation, or invalid UTF-8."""
    nums = [m for m in NUMBER.finditer(data)  # numbers, not digits inside a string value
            if len(re.findall(rb'(?<!\\)"', data[:m.start()])) % 2 == 0]
    pick = rng.random()
    if nums and pick < 0.7:
        m = rng.choice(nums)
        return data[:m.start()] + rng.choice(values).encode() + data[m.end():]
    if pick < 0.9:
        return data[:rng.randrange(1, max(2, len(data.rstrip()) - 1))]
    i = rng.randrange(len(data))
    return data[:i] + b"\xff\xfe" + data[i:]


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
