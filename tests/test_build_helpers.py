"""Shared fixtures of the build tests: small simulated recordings with a lut calibration, and one
reference dataset built from them (both read-only: copy before changing anything).

Test modules use them with `pytest_plugins = ["test_build_helpers"]`.
"""

from __future__ import annotations

import hashlib
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

SIZE = (96, 128)
#: Small shards so that both kinds have several, the last one partial (static: 4 per shard).
SHARD_MB = 0.15
BUILD_ARGS = ("--shard-mb", str(SHARD_MB), "--quiet")


def make_recordings(root: Path) -> Path:
    """Simulate 6 static frames, 9 sequences of 8 frames and 6 presses, then calibrate (lut)
    with `vtsbench calibrate RECORDINGS --out RECORDINGS/calibration.safetensors`."""
    from typer.testing import CliRunner

    from vtsbench.cli import app
    from vtsbench.sim.simulate import simulate

    simulate(root, seed=3, n_static=6, n_sequences=9, n_presses=6, size=SIZE, mm_per_px=0.08,
             n_sessions=3, progress=False)
    res = CliRunner().invoke(app, ["calibrate", str(root), "--out",
                                   str(root / "calibration.safetensors"), "--method", "lut"])
    assert res.exit_code == 0, res.output
    return root


def tree_bytes(root: Path) -> dict[str, str]:
    """sha256 of every file under root, hidden ones included, by relative path."""
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def copy_recordings(src: Path, dst: Path) -> Path:
    """A private copy of a recordings folder that a test may break."""
    return Path(shutil.copytree(src, dst))


def cli(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    """Run `python -m vtsbench ARGS` and capture its output."""
    return subprocess.run([sys.executable, "-m", "vtsbench", *args], capture_output=True,
                          text=True, timeout=timeout)


@pytest.fixture(scope="session")
def sim_recordings(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Simulated recordings with calibration.safetensors (read-only)."""
    return make_recordings(tmp_path_factory.mktemp("build-rec") / "rec")


@pytest.fixture(scope="session")
def built(sim_recordings: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The reference dataset: built in this process with one worker (read-only)."""
    from vtsbench.dataset.build import BuildOptions, build

    out = tmp_path_factory.mktemp("build-ref") / "ds"
    build(sim_recordings, out, BuildOptions(shard_mb=SHARD_MB))
    return out


def write_info_text(ds: Path, text: str) -> None:
    """Write meta/info.json as given (a document the dataclass cannot hold, such as a repeated
    key), its info_sha256, when it has one, recomputed to match."""
    from vtsbench.dataset.format.info import INFO_HASH, _with_info_hash

    if f'"{INFO_HASH}": "' in text:
        text = _with_info_hash(text, hashlib.sha256(_with_info_hash(text, "").encode())
                               .hexdigest())
    (ds / "meta" / "info.json").write_text(text)


def rehash(ds: Path, edit=None) -> None:
    """Recompute every checksum of a dataset after a test changed its files, as a deliberate
    change would: each listed file's sha256, the split files' sha256 in `splits`,
    dataset_sha256 and info_sha256 (a 1.0 document without one stays without). edit(doc) may
    change the info.json document first."""
    import json

    from vtsbench.dataset.format.info import INFO_HASH, dataset_checksum

    doc = json.loads((ds / "meta" / "info.json").read_text())
    if edit is not None:
        edit(doc)
    for rel in doc["files"]:
        if (ds / rel).is_file():
            doc["files"][rel] = hashlib.sha256((ds / rel).read_bytes()).hexdigest()
    for name in doc["splits"]:
        path = ds / "meta" / "splits" / f"{name}.json"
        if path.is_file():
            doc["splits"][name] = hashlib.sha256(path.read_bytes()).hexdigest()
    doc["dataset_sha256"] = dataset_checksum(doc["files"])
    if INFO_HASH in doc:
        doc[INFO_HASH] = doc.pop(INFO_HASH)  # last, as the build writes it
    write_info_text(ds, json.dumps(doc, indent=1) + "\n")


def rewrite_index(ds: Path, kind: str, change) -> None:
    """Rewrite index/<kind>.parquet with change(table) -> table, then rehash."""
    import pyarrow.parquet as pq

    from vtsbench.dataset.format.index import PARQUET_OPTIONS

    path = ds / "index" / f"{kind}.parquet"
    pq.write_table(change(pq.read_table(path)), path, **PARQUET_OPTIONS)
    rehash(ds)


def edit_json(path: Path, change) -> None:
    """Rewrite a JSON file of a dataset with change(doc) (which edits doc in place)."""
    import json

    doc = json.loads(path.read_text())
    change(doc)
    path.write_text(json.dumps(doc, indent=2))


def depth_attrs_to_1_0(ds: Path) -> None:
    """Give the depth arrays the `scale` attribute format 1.0 wrote (1.1 writes the CF
    `scale_factor`), in each array's zarr.json and the consolidated metadata; hashes recomputed."""
    def to_1_0(attrs: dict) -> None:
        attrs["scale"] = attrs.pop("scale_factor")

    for kind in ("static", "slip"):
        group = ds / "data" / f"{kind}.zarr"
        edit_json(group / "depth" / "zarr.json", lambda d: to_1_0(d["attributes"]))
        edit_json(group / "zarr.json", lambda d: to_1_0(
            d["consolidated_metadata"]["metadata"]["depth"]["attributes"]))
    rehash(ds)


def use_dataset(ds: Path, **kwargs: object) -> None:
    """Everything a user does with a dataset: load, every part of every split, a read of every
    array and of the index fields of both kinds."""
    import vtsbench

    d = vtsbench.load(ds, **kwargs)
    for name in d.splits:
        for part in d.parts(name):
            d.split(name, part)
    for kind in ("static", "slip"):
        view = d.view(kind)
        view.read(slice(None), arrays=d.arrays)
        view.metas(range(len(view)))


def run(*args: object):
    """`vtsbench ARGS` through typer's test runner (output and exit code, in this process)."""
    from typer.testing import CliRunner

    from vtsbench.cli import app

    return CliRunner().invoke(app, [str(a) for a in args])


def clean(res, code: int, *names: object) -> str:
    """Assert a clean failure: the exit code, no traceback, the names in the message."""
    out = res.output
    assert res.exit_code == code, out
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert "Traceback" not in out
    for n in names:
        assert str(n) in out, (n, out)
    return out


@pytest.fixture
def ds(built: Path, tmp_path: Path) -> Path:
    """A copy of the reference dataset that a test may damage."""
    return Path(shutil.copytree(built, tmp_path / "ds"))


@pytest.fixture
def rec(sim_recordings: Path, tmp_path: Path) -> Path:
    """A copy of the reference recordings that a test may change."""
    return Path(shutil.copytree(sim_recordings, tmp_path / "rec"))
