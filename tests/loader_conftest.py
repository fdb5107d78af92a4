"""Fixtures of the loader tests: one small dataset built per test session, direct Zarr reads
to compare with, and a loopback HTTP server (with byte ranges) serving a folder.

Test modules use it with `pytest_plugins = ["loader_conftest"]`.
"""

from __future__ import annotations

import contextlib
import re
import shutil
import threading
from collections.abc import Callable, Iterator, Sequence
from functools import partial
from http import HTTPStatus
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np
import pytest

SIZE = (96, 128)


def build_dataset(root: Path) -> Path:
    """Simulate recordings, calibrate and build a dataset under root; returns the dataset.

    Shards of about 1 MB, so the slip arrays span several shard files.
    """
    from vtsbench.dataset.build import BuildOptions, build
    from vtsbench.depth.calibration import calibrate, save_calibration
    from vtsbench.sim.simulate import simulate

    rec = root / "recordings"
    simulate(rec, seed=0, n_static=6, n_sequences=9, n_presses=6, size=SIZE, mm_per_px=0.08,
             progress=False)
    run = calibrate(rec, method="poly")
    save_calibration(run.calibration, rec / "calibration.safetensors")
    build(rec, root / "dataset", BuildOptions(shard_mb=1.0))
    return root / "dataset"


@pytest.fixture(scope="session")
def vts_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The path of a small built dataset (read-only: copy it before changing anything)."""
    return build_dataset(tmp_path_factory.mktemp("loader-data"))


@pytest.fixture
def dataset_copy(vts_dataset: Path, tmp_path: Path) -> Path:
    """A private copy of the dataset that a test may change."""
    return Path(shutil.copytree(vts_dataset, tmp_path / "ds"))


def read_zarr_rows(dataset: Path, kind: str, name: str, rows: Sequence[int]) -> np.ndarray:
    """Rows of one array read with zarr directly (the reference the loader is checked against)."""
    import zarr

    arr = zarr.open_group(str(dataset / "data" / f"{kind}.zarr"), mode="r")[name]
    return np.stack([arr[int(r)] for r in rows]) if len(rows) else arr[0:0]


@pytest.fixture(scope="session")
def zarr_rows() -> Callable[[Path, str, str, Sequence[int]], np.ndarray]:
    """read_zarr_rows(dataset, kind, array, rows): the reference reads."""
    return read_zarr_rows


class RangeHandler(SimpleHTTPRequestHandler):
    """Static files with `Range: bytes=a-b | a- | -n` support (http.server ignores ranges)."""

    def log_message(self, format: str, *args: object) -> None:
        pass

    def send_head(self):  # type: ignore[override]
        rng = self.headers.get("Range")
        path = Path(self.translate_path(self.path))
        if not rng or not path.is_file():
            return super().send_head()
        m = re.fullmatch(r"bytes=(\d*)-(\d*)", rng.strip())
        size = path.stat().st_size
        if not m or m.groups() == ("", ""):
            self.send_error(HTTPStatus.REQUESTED_RANGE_NOT_SATISFIABLE)
            return None
        a, b = m.groups()
        if a == "":
            start, end = max(0, size - int(b)), size - 1
        else:
            start, end = int(a), min(size - 1, int(b)) if b else size - 1
        if start > end or start >= size:
            self.send_error(HTTPStatus.REQUESTED_RANGE_NOT_SATISFIABLE)
            return None
        fh = open(path, "rb")  # noqa: SIM115 - closed by copyfile's caller
        fh.seek(start)
        self.send_response(HTTPStatus.PARTIAL_CONTENT)
        self.send_header("Content-Type", "application/octet-stream")
        self.send_header("Content-Range", f"bytes {start}-{end}/{size}")
        self.send_header("Content-Length", str(end - start + 1))
        self.end_headers()
        self._left = end - start + 1
        return fh

    def copyfile(self, source, outputfile):  # type: ignore[override]
        left = getattr(self, "_left", None)
        if left is None:
            return super().copyfile(source, outputfile)
        outputfile.write(source.read(left))
        self._left = None
        return None


@contextlib.contextmanager
def serve(folder: Path) -> Iterator[str]:
    """Serve folder on 127.0.0.1 (a free port) in a thread; yields the base URL."""
    handler = partial(RangeHandler, directory=str(folder))
    server = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    server.daemon_threads = True
    server.timeout = 5
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05},
                              daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=10)


@pytest.fixture(scope="module")
def http_root(vts_dataset: Path) -> Iterator[str]:
    """The base URL of a loopback server whose /ds is the test dataset."""
    with serve(vts_dataset.parent) as base:
        yield f"{base}/{vts_dataset.name}"


def predict_and_eval(recipe: str, checkpoint: Path, dataset: Path, split: str,
                     work: Path, name: str) -> dict:
    """`vtsbench predict` then `vtsbench eval --out` through the CLI, as a user runs them;
    checks the submission's metadata (method = recipe name, a measured latency) and returns
    the eval's metrics.json."""
    import json

    from typer.testing import CliRunner

    from vtsbench.cli import app

    runner = CliRunner()
    sub = work / f"{name}.csv"
    res = runner.invoke(app, ["predict", recipe, str(checkpoint), "--dataset", str(dataset),
                              "--split", split, "--out", str(sub)])
    assert res.exit_code == 0, res.output
    meta = json.loads((work / f"{name}.meta.json").read_text())
    assert meta["method"] == Path(recipe).stem and meta["latency_ms_per_sample_median"] > 0
    res = runner.invoke(app, ["eval", str(sub), "--dataset", str(dataset), "--split", split,
                              "--out", str(work / "ev"), "--no-figures"])
    assert res.exit_code == 0, res.output
    return json.loads((work / "ev" / "metrics.json").read_text())
