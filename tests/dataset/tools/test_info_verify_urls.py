"""`vtsbench info` and `vtsbench verify` take the URLs `vtsbench.load` takes: file:// and a
loopback HTTP server (fsspec), with the same answers as for the folder."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from vtsbench.cli import app
from vtsbench.dataset.tools.info import summarise
from vtsbench.dataset.tools.verify import verify


def test_info_of_a_file_url_and_of_http_equals_the_folder(vts_dataset: Path,
                                                          http_root: str) -> None:
    folder = summarise(vts_dataset)
    for url in (vts_dataset.as_uri(), http_root):
        s = summarise(url)
        assert s.info.dataset_sha256 == folder.info.dataset_sha256
        assert s.by_object == folder.by_object and s.raw_bytes == folder.raw_bytes
        # over HTTP only the files info.json lists (and itself) are seen: every file of a build
        assert s.sizes == folder.sizes, url


def test_verify_of_urls(vts_dataset: Path, http_root: str) -> None:
    for url in (vts_dataset.as_uri(), http_root):
        report = verify(url, decode=True)
        assert report.problems == [], url
        assert report.files == len(summarise(vts_dataset).info.files)


def test_verify_over_http_finds_a_damaged_file(vts_dataset: Path, tmp_path: Path) -> None:
    from tests.fixtures.serve import serve

    ds = tmp_path / "ds"
    shutil.copytree(vts_dataset, ds)
    shard = next(p for p in sorted((ds / "data").rglob("*")) if p.is_file()
                 and "/c/" in p.as_posix())
    data = bytearray(shard.read_bytes())
    data[len(data) // 2] ^= 0xFF
    shard.write_bytes(bytes(data))
    with serve(tmp_path) as base:
        report = verify(f"{base}/ds", decode=False)
    rel = shard.relative_to(ds).as_posix()
    assert any(p.startswith(f"{rel}: sha256 mismatch") for p in report.problems)


def test_cli_info_and_verify_take_urls(vts_dataset: Path, http_root: str) -> None:
    for url in (vts_dataset.as_uri(), http_root):
        res = CliRunner().invoke(app, ["info", url], env={"COLUMNS": "160"})
        assert res.exit_code == 0, res.output
        assert "checksum" in res.output.lower() or "sha256" in res.output.lower()
        res = CliRunner().invoke(app, ["verify", url, "--quick"])
        assert res.exit_code == 0, res.output
        assert "0 problem(s)" in res.output


def test_a_url_that_is_no_dataset_is_one_line(http_root: str) -> None:
    res = CliRunner().invoke(app, ["info", http_root + "/index"])
    assert res.exit_code == 2 and len(res.stderr.strip().splitlines()) == 1
    assert "not a vtsbench dataset" in res.stderr
    res = CliRunner().invoke(app, ["verify", "nosuchproto://x/y"])
    assert res.exit_code == 2 and len(res.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("where", ["folder", "url"])
def test_missing_dataset_is_one_line(tmp_path: Path, where: str) -> None:
    target = tmp_path / "none"
    arg = str(target) if where == "folder" else target.as_uri()
    res = CliRunner().invoke(app, ["verify", arg])
    assert res.exit_code == 2 and "no such dataset folder" in res.stderr
