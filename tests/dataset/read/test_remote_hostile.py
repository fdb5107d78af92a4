"""Datasets served over HTTP on 127.0.0.1 by hostile or limited servers: metadata naming files
outside the dataset, a server without byte ranges (as `python -m http.server`), a slow server,
an endless info.json, and seeded fuzzing of served metadata. Every failure is one line (exit 1
or 2, no traceback) within a few seconds; nothing is written outside the temporary copy."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import random
import re
import shutil
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Iterator
from functools import partial
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import vtsbench
from vtsbench.cli import app
from vtsbench.dataset.format.info import dataset_checksum
from vtsbench.dataset.read.location import Location, safe_rel
from vtsbench.errors import VtsError

#: Seconds of remote fuzzing in all (VTSBENCH_FUZZ_SECONDS fuzzes longer).
FUZZ_SECONDS = float(os.environ.get("VTSBENCH_FUZZ_SECONDS", "2.5"))
#: Set by a test to end the slow handlers' waits at teardown.
STOP = threading.Event()


class Quiet(SimpleHTTPRequestHandler):
    """http.server's static files (no byte ranges: a ranged GET gets 200 and the whole file),
    counting GETs per path."""

    gets: Counter[str]

    def log_message(self, format: str, *args: object) -> None:
        pass

    def do_GET(self) -> None:
        self.gets[self.path] += 1
        super().do_GET()


class Slow(Quiet):
    """Answers paths matching `slow` only after a long wait."""

    slow = re.compile(r"")

    def do_GET(self) -> None:
        if self.slow.search(self.path):
            STOP.wait(30)
        super().do_GET()

    def do_HEAD(self) -> None:
        if self.slow.search(self.path):
            STOP.wait(30)
        super().do_HEAD()


class Endless(Quiet):
    """Serves meta/info.json as a body that never ends."""

    def do_GET(self) -> None:
        if not self.path.endswith("meta/info.json"):
            return super().do_GET()
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        self.end_headers()
        with contextlib.suppress(OSError):
            self.wfile.write(b'{"name": "')
            while not STOP.is_set():
                self.wfile.write(b"x" * 65536)
        return None


@contextlib.contextmanager
def serving(folder: Path, handler: type[Quiet], **attrs: object) -> Iterator[tuple[str, Counter]]:
    """Serve folder with handler on a free port of 127.0.0.1; yields (base URL, GET counts)."""
    gets: Counter[str] = Counter()
    cls = type(handler.__name__, (handler,), {"gets": gets, **attrs})
    server = ThreadingHTTPServer(("127.0.0.1", 0), partial(cls, directory=str(folder)))
    server.daemon_threads = True
    server.handle_error = lambda *_: None  # type: ignore[method-assign] # a client that left
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05},
                              daemon=True)
    STOP.clear()
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}", gets
    finally:
        STOP.set()
        server.shutdown()
        server.server_close()
        thread.join(timeout=10)


def one_line_failure(res, code: int | tuple[int, ...] = 2) -> str:
    """The CLI failed cleanly: the exit code, one line, no traceback."""
    codes = (code,) if isinstance(code, int) else code
    assert res.exit_code in codes, res.output
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert "Traceback" not in res.output
    return res.output


@pytest.fixture
def served(vts_dataset: Path, tmp_path: Path) -> Path:
    """A private copy of the dataset in tmp_path/www/ds (served from tmp_path/www)."""
    return Path(shutil.copytree(vts_dataset, tmp_path / "www" / "ds"))


def info_text_with_hash(doc: dict) -> str:
    """info.json text of doc with its info_sha256 recomputed (as a build writes it)."""
    doc = {k: v for k, v in doc.items() if k != "info_sha256"}
    text = json.dumps({**doc, "info_sha256": ""}, indent=1) + "\n"
    digest = hashlib.sha256(text.encode()).hexdigest()
    return text.replace('"info_sha256": ""', f'"info_sha256": "{digest}"')


def rehash(ds: Path, changed: str | None = None, doc: dict | None = None) -> None:
    """Record a changed file's sha256 in info.json and recompute dataset_sha256 and
    info_sha256, as someone forging a consistent dataset would."""
    info = ds / "meta" / "info.json"
    doc = json.loads(info.read_text()) if doc is None else doc
    if changed is not None:
        doc["files"][changed] = hashlib.sha256((ds / changed).read_bytes()).hexdigest()
    doc["dataset_sha256"] = dataset_checksum(doc["files"])
    info.write_text(info_text_with_hash(doc))


# -- path traversal ------------------------------------------------------------------------------

@pytest.mark.parametrize("rel", ["../../escaped.txt", "/etc/passwd", "meta/../../x", "a\\..\\b",
                                 "a//b", "./a", "a/.", "", "x\x00y", "C:/x", "%2e%2e/x", "a?b"])
def test_unsafe_relative_paths_are_refused_naming_info_json(rel: str) -> None:
    with pytest.raises(VtsError, match="unsafe file path") as e:
        Location("http://127.0.0.1:1/ds").path(rel)
    assert str(e.value).startswith("http://127.0.0.1:1/ds/meta/info.json: ")
    assert "\n" not in str(e.value)
    with pytest.raises(VtsError, match="unsafe file path"):
        safe_rel(rel, "info.json")
    assert safe_rel("data/slip.zarr/rgb/c/0/0/0/0/0", "i") == "data/slip.zarr/rgb/c/0/0/0/0/0"


def test_verify_refuses_a_served_file_list_leaving_its_folder(served: Path, tmp_path: Path,
                                                              monkeypatch) -> None:
    """info.json (hash recomputed) lists ../../escaped.txt; the server answers it. Before the
    fix `verify --quick` wrote it beside its temporary folder."""
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    (served.parent / "escaped.txt").write_text("pwned")  # /ds/../../escaped.txt -> /escaped.txt
    doc = json.loads((served / "meta" / "info.json").read_text())
    doc["files"]["../../escaped.txt"] = hashlib.sha256(b"pwned").hexdigest()
    rehash(served, doc=doc)
    with serving(served.parent, Quiet) as (base, _):
        for args in (["verify", f"{base}/ds", "--quick"], ["verify", f"{base}/ds"]):
            res = CliRunner().invoke(app, args)
            out = one_line_failure(res)
            assert f"{base}/ds/meta/info.json: " in out and "'../../escaped.txt'" in out
            assert len(res.stderr.strip().splitlines()) == 1
    assert list(scratch.rglob("escaped.txt")) == []
    assert not list(scratch.iterdir())  # nothing left behind either


def test_the_remote_copy_itself_refuses_a_path_leaving_it(served: Path, tmp_path: Path,
                                                          monkeypatch) -> None:
    """Whatever info.json's validation lets through, the copy `verify` makes of a remote
    dataset joins no listed path outside its temporary folder."""
    import dataclasses

    from vtsbench.dataset.format.info import load_info
    from vtsbench.dataset.read import remote

    scratch = tmp_path / "scratch"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    (served.parent / "escaped.txt").write_text("pwned")
    info = load_info(served)
    evil = dataclasses.replace(info, files={**info.files, "../../escaped.txt": "0" * 64})
    monkeypatch.setattr(remote, "remote_info", lambda loc: evil)
    with serving(served.parent, Quiet) as (base, gets):
        with pytest.raises(VtsError, match=r"unsafe file path '\.\./\.\./escaped\.txt'") as e, \
                remote.local_copy(f"{base}/ds"):
            pass
        assert str(e.value).startswith(f"{base}/ds/meta/info.json: ")
        assert not [p for p in gets if "/c/" in p]  # refused before fetching anything
    assert not list(scratch.iterdir())


def test_location_reads_the_info_json_the_layout_names() -> None:
    from vtsbench.dataset.format import layout
    from vtsbench.dataset.read import location

    assert location.INFO_PATH is layout.INFO_PATH


def test_load_refuses_a_split_file_path_leaving_the_dataset(served: Path) -> None:
    """A split named in info.json is read at meta/splits/<name>.json: never outside."""
    doc = json.loads((served / "meta" / "info.json").read_text())
    name = sorted(doc["splits"])[0]
    doc["splits"]["../../../evil"] = doc["splits"].pop(name)
    doc["counts"]["splits"]["../../../evil"] = doc["counts"]["splits"].pop(name)
    rehash(served, doc=doc)
    with serving(served.parent, Quiet) as (base, gets):
        for where in (served, f"{base}/ds"):
            with pytest.raises(VtsError) as e:  # refused on loading, or on reading the split
                vtsbench.load(where).split_file("../../../evil")
            assert "meta/info.json: " in str(e.value) and "../../../evil" in str(e.value)
        assert not [p for p in gets if "evil" in p]


# -- a server without byte ranges ----------------------------------------------------------------

def test_a_server_ignoring_ranges_reads_every_array_right(served: Path, vts_dataset: Path) -> None:
    """As `python -m http.server`: before the fix the arrays read as a damaged shard."""
    local = vtsbench.load(vts_dataset)
    with serving(served.parent, Quiet) as (base, gets):
        ds = vtsbench.load(f"{base}/ds")
        for kind in ("static", "slip"):
            view, want = ds.view(kind), local.view(kind)
            for i in range(len(view)):  # sample by sample: byte ranges of each shard
                for name, a in view[i].items():
                    np.testing.assert_array_equal(a, want[i][name])
            n = len(view)
            got = view.read(list(range(n))[::-1], ("rgb", "depth", "contact"))
            for name, a in want.read(list(range(n))[::-1], ("rgb", "depth", "contact")).items():
                np.testing.assert_array_equal(got[name], a)
        shards = {p: n for p, n in gets.items() if "/c/" in p}
        files = [p for p in served.rglob("*") if p.is_file() and "/c/" in p.as_posix()]
        assert len(shards) == len(files) and max(shards.values()) == 1, shards  # once each
        res = CliRunner().invoke(app, ["verify", f"{base}/ds"])
        assert res.exit_code == 0 and "0 problem(s)" in res.output, res.output


def test_a_server_with_ranges_is_read_in_ranges(served: Path) -> None:
    """The fallback stays off for a server that honours Range: no whole shard is fetched for
    one sample of a shard of several."""
    from tests.fixtures.serve import serve

    with serve(served.parent) as base:
        ds = vtsbench.load(f"{base}/ds")
        from vtsbench.dataset.read.location import http_filesystem_class

        fs_cls = http_filesystem_class()
        ds.slip.read([0], ("rgb",))
        fs = ds._kinds["slip"]._group.store._store.fs
        assert isinstance(fs, fs_cls) and not fs.no_ranges


# -- timeouts and size limits --------------------------------------------------------------------

def test_a_slow_server_times_out_in_one_line(served: Path, monkeypatch) -> None:
    monkeypatch.setenv("VTSBENCH_REMOTE_READ_TIMEOUT", "0.5")
    with serving(served.parent, Slow, slow=re.compile(r"info\.json")) as (base, _):
        t0 = time.perf_counter()
        for args in (["info", f"{base}/ds"], ["verify", f"{base}/ds", "--quick"]):
            res = CliRunner().invoke(app, args)
            out = one_line_failure(res)
            assert f"{base}/ds/meta/info.json: no answer in time" in out
            assert "VTSBENCH_REMOTE_READ_TIMEOUT" in out
        with pytest.raises(VtsError, match="no answer in time"):
            vtsbench.load(f"{base}/ds")
        assert time.perf_counter() - t0 < 4


def test_slow_shards_time_out_in_one_line(served: Path, monkeypatch) -> None:
    """Metadata answers at once, shards never: reading an array fails in one line (not a
    'damaged shard', not a hang)."""
    monkeypatch.setenv("VTSBENCH_REMOTE_READ_TIMEOUT", "0.5")
    with serving(served.parent, Slow, slow=re.compile(r"/c/")) as (base, _):
        ds = vtsbench.load(f"{base}/ds")
        t0 = time.perf_counter()
        with pytest.raises(VtsError, match="no answer in time") as e:
            ds.slip.read([0], ("rgb",))
        assert "\n" not in str(e.value) and "/c/" in str(e.value)
        assert time.perf_counter() - t0 < 4


def test_an_unreachable_server_is_one_line(monkeypatch) -> None:
    import socket

    monkeypatch.setenv("VTSBENCH_REMOTE_CONNECT_TIMEOUT", "0.5")
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    res = CliRunner().invoke(app, ["info", f"http://127.0.0.1:{port}/ds"])
    assert "cannot read" in one_line_failure(res)


def test_an_endless_info_json_stops_at_the_limit(served: Path, monkeypatch) -> None:
    monkeypatch.setenv("VTSBENCH_REMOTE_METADATA_MB", "1")
    with serving(served.parent, Endless) as (base, _):
        t0 = time.perf_counter()
        for args in (["info", f"{base}/ds"], ["verify", f"{base}/ds", "--quick"]):
            out = one_line_failure(CliRunner().invoke(app, args))
            assert f"{base}/ds/meta/info.json: over the size limit of 1048576 bytes" in out
        with pytest.raises(VtsError, match="over the size limit"):
            vtsbench.load(f"{base}/ds")
        assert time.perf_counter() - t0 < 4


def test_an_oversized_zarr_json_is_refused(served: Path, monkeypatch) -> None:
    """A group's zarr.json is metadata too: bounded before zarr parses it."""
    monkeypatch.setenv("VTSBENCH_REMOTE_METADATA_MB", "0.01")  # 10 KiB: info.json fits
    meta = served / "data" / "slip.zarr" / "zarr.json"
    meta.write_bytes(meta.read_bytes().rstrip() + b" " * 20_000 + b"\n")
    rehash(served, "data/slip.zarr/zarr.json")
    with serving(served.parent, Quiet) as (base, _):
        ds = vtsbench.load(f"{base}/ds")
        with pytest.raises(VtsError, match="over the size limit") as e:
            ds.slip.read([0], ("rgb",))
        assert str(e.value).startswith(f"{base}/ds/data/slip.zarr/zarr.json: ")


def test_a_bad_setting_is_one_line(monkeypatch, http_root: str) -> None:
    monkeypatch.setenv("VTSBENCH_REMOTE_READ_TIMEOUT", "soon")
    out = one_line_failure(CliRunner().invoke(app, ["info", http_root]))
    assert "VTSBENCH_REMOTE_READ_TIMEOUT='soon'" in out


# -- fuzz ------------------------------------------------------------------------------------------

def _mutate(data: bytes, rng: random.Random) -> bytes:
    from tests.fixtures.hostile import HOSTILE, TYPED, mutate_json

    pick = rng.random()
    if pick < 0.15:  # a file path that leaves the dataset
        return data.replace(b'"meta/', b'"../../meta/', 1)
    return mutate_json(data, rng, HOSTILE + TYPED)


def test_fuzz_served_metadata(served: Path, monkeypatch, capsys) -> None:
    """Mutated info.json (hash recomputed), split file and zarr.json (recorded in info.json with
    their new hashes), served over HTTP: `info`, `verify --quick` and loading and reading end
    in one line, never a traceback or a write outside the temporary folder."""
    scratch = served.parent.parent / "scratch"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    monkeypatch.setenv("VTSBENCH_REMOTE_READ_TIMEOUT", "5")
    split = next(iter(sorted((served / "meta" / "splits").glob("*.json"))))
    targets = [served / "meta" / "info.json", split, served / "data" / "slip.zarr" / "zarr.json"]
    origs = {t: t.read_bytes() for t in [*targets, served / "meta" / "info.json"]}
    runner = CliRunner()
    n, bad = 0, []
    with serving(served.parent, Quiet) as (base, _):
        url = f"{base}/ds"
        for seed, target in enumerate(targets):
            rng = random.Random(seed)
            t0 = time.perf_counter()
            while time.perf_counter() - t0 < FUZZ_SECONDS / len(targets) or n < 2 * (seed + 1):
                for t, data in origs.items():
                    t.write_bytes(data)
                data = _mutate(target.read_bytes(), rng)
                target.write_bytes(data)
                rel = target.relative_to(served).as_posix()
                if rel == "meta/info.json":
                    with contextlib.suppress(ValueError, RecursionError):
                        rehash(served, doc=json.loads(data))
                else:
                    rehash(served, rel)
                n += 1
                # `info` asks the server for every file's size: slower, run on some inputs
                for args in (["info", url], ["verify", url, "--quick"])[n % 4 != 1:]:
                    res = runner.invoke(app, args, env={"COLUMNS": "160"})
                    if res.exit_code != 0 and (
                            res.exit_code not in (1, 2) or "Traceback" in res.output
                            or not isinstance(res.exception, SystemExit)):
                        bad.append(f"{rel} #{n} {args[0]}: {res.exit_code} {res.exception!r}")
                try:
                    ds = vtsbench.load(url)
                    ds.slip.read([0, len(ds.slip) - 1], ds.arrays)
                except VtsError as e:
                    if "\n" in str(e):
                        bad.append(f"{rel} #{n} load: {e}")
                except Exception as e:  # anything else is a defect
                    bad.append(f"{rel} #{n} load: {type(e).__name__}: {e}"[:300])
    assert not list(scratch.rglob("*.json")), "a file outside the temporary copy"
    with capsys.disabled():
        print(f"\nremote fuzz: {n} inputs, {n - len(bad)} handled cleanly")
    assert not bad, bad[:5]
