"""Time of `vtsbench eval` as a whole process (start-up included) on a 1,200-sequence
submission: the paper's unseen-object test (5 held-out objects, 400 sequences per state).

Run: .venv/bin/python benchmarks/eval.py [--repeats 5]

Fakes a dataset in a temporary folder with only what scoring reads through `vtsbench.load`:
meta/info.json, the split file and the two indexes (1,200 slip sequences, no static sample; no
arrays). The submission predicts the
state right 95.5 % of the time and the direction 91.5 % (errors mostly on the adjacent bin).
Reports the best and median wall time of `vtsbench eval` with and without the PNGs, and of
`vtsbench --help` (the start-up floor); prints the machine line; removes what it wrote.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from machine import machine  # benchmarks/machine.py: the shared machine line

from vtsbench.labels import STATES

N_PER_STATE = 400
OBJECTS = [f"obj{i:02d}" for i in range(15)]


def fake_dataset(root: Path) -> Path:
    """info.json, meta/splits/unseen_objects.json, index/slip.parquet of 1,200 sequences and an
    empty index/static.parquet; loads with `vtsbench.load`."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from vtsbench.dataset.format.index import index_schema, kind_counts
    from vtsbench.dataset.format.info import Counts, DatasetInfo, ZarrSettings
    from vtsbench.dataset.format.records import SplitFile
    from vtsbench.dataset.splits import write_splits

    rng = np.random.default_rng(0)
    ds = root / "dataset"
    n = 3 * N_PER_STATE
    state = np.repeat(np.arange(3), N_PER_STATE)
    ids = [f"seq{i:05d}" for i in range(n)]
    objs = [OBJECTS[10 + i % 5] for i in range(n)]
    direction = np.where(state == 2, rng.integers(0, 8, n), -1)
    rows = {c: [None] * n for c in index_schema("slip").names}
    rows.update(sample_id=ids, row=list(range(n)), object=objs,
                class_idx=[OBJECTS.index(o) for o in objs], session=["s0"] * n,
                sensor=["sim"] * n, mm_per_px_x=[0.03] * n, mm_per_px_y=[0.03] * n,
                state=[STATES[s] for s in state], state_idx=state.tolist(),
                direction=[None if d < 0 else int(d) for d in direction], source=["fake"] * n)
    (ds / "index").mkdir(parents=True)
    tables = {"slip": pa.table(rows, schema=index_schema("slip")),
              "static": pa.table({c: [] for c in index_schema("static").names},
                                 schema=index_schema("static"))}
    for kind, table in tables.items():
        pq.write_table(table, ds / "index" / f"{kind}.parquet")
    sp = SplitFile("unseen_objects", "slip", "fake", 0, {"train": [], "test": ids},
                   ["object:test"], {})
    shas = write_splits(ds / "meta" / "splits", [sp])
    info = DatasetInfo(name="fake", vtsbench_version="0.1.0", frames_per_sequence=8,
                       resolution=(480, 640), objects=OBJECTS,
                       counts=Counts(kind_counts(tables["static"], "static"),
                                     kind_counts(tables["slip"], "slip"),
                                     {"unseen_objects": {"train": 0, "test": n}}),
                       shapes={"static": {"rgb": (0, 480, 640, 3), "depth": (0, 480, 640),
                                          "contact": (0, 480, 640)},
                               "slip": {"rgb": (n, 8, 480, 640, 3), "depth": (n, 8, 480, 640),
                                        "contact": (n, 8, 480, 640)}},
                       zarr=ZarrSettings({"static": 1, "slip": 1}), splits=shas,
                       dataset_sha256="0" * 64)
    (ds / "meta" / "info.json").write_text(info.to_json())
    import vtsbench

    vtsbench.load(ds).split_file("unseen_objects")  # the fake must pass the reader's checks
    sub = root / "sub.csv"
    st_pred = np.where(rng.random(n) < 0.955, state, (state + 1) % 3)
    miss = rng.random(n) >= 0.915
    dir_pred = np.where(miss, (direction + rng.choice([1, 7, 1, 7, 2, 4], n)) % 8, direction)
    lines = ["sample_id,task,pred"]
    for i, s in enumerate(ids):
        lines.append(f"{s},state,{st_pred[i]}")
        lines.append(f"{s},direction,{dir_pred[i] % 8}")
    sub.write_text("\n".join(lines) + "\n")
    (root / "sub.meta.json").write_text(json.dumps({"method": "fake", "dataset_version": "1.0.0",
                                                     "seeds": [0]}))
    return ds


def timed(cmd: list[str], repeats: int) -> list[float]:
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        out.append(time.perf_counter() - t0)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    exe = str(Path(sys.executable).with_name("vtsbench"))
    work = Path(tempfile.mkdtemp(prefix="vtsbench-eval-"))
    try:
        ds = fake_dataset(work)
        base = [exe, "eval", str(work / "sub.csv"), "--dataset", str(ds), "--split",
                "unseen_objects"]
        runs = {"`vtsbench --help` (start-up floor)": [exe, "--help"],
                "`vtsbench eval` (print only)": base,
                "`vtsbench eval --out DIR --no-figures` (+ metrics.json, report.md)":
                    [*base, "--out", str(work / "ev"), "--no-figures"],
                "`vtsbench eval --out DIR` (+ 2 PNGs)": [*base, "--out", str(work / "ev")]}
        print("| command (1,200 sequences, 2,400 rows) | best (s) | median (s) |")
        print("|---|---:|---:|")
        for name, cmd in runs.items():
            t = timed(cmd, args.repeats)
            print(f"| {name} | {min(t):.2f} | {statistics.median(t):.2f} |")
        print(f"\nMachine: {machine()}")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
