"""vtsbench build end to end: simulate -> calibrate -> build -> verify -> info -> load."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from tests.fixtures.cli import cli
from tests.fixtures.datasets import BUILD_ARGS, tree_bytes
from vtsbench.cli import app


def _source(text: str) -> tuple[str, int, int]:
    path, rng = text.rsplit("[", 1)
    a, b = rng.rstrip("]").split(":")
    return path, int(a), int(b)


def test_layout_and_verify(built: Path) -> None:
    names = tree_bytes(built)
    for rel in ("README.md", "meta/info.json", "meta/build_report.json", "index/static.parquet",
                "index/slip.parquet", "preview/static.parquet", "preview/slip.parquet",
                "data/static.zarr/zarr.json", "data/slip.zarr/rgb/zarr.json"):
        assert rel in names, rel
    assert not any(n.startswith(".") or "/." in n for n in names)  # no build state left
    assert not (built.parent / f".{built.name}.partial").exists()
    res = CliRunner().invoke(app, ["verify", str(built)])
    assert res.exit_code == 0, res.output
    assert "0 problem(s)" in res.output
    info = json.loads((built / "meta/info.json").read_text())
    assert set(info["files"]) == set(names) - {"meta/info.json"}
    assert info["shapes"]["slip"]["rgb"] == [9, 8, 96, 128, 3]
    assert info["zarr"]["samples_per_shard"] == {"static": 4, "slip": 1}
    assert info["calibration"]["method"] == "lut"
    assert "workers" not in json.dumps(info["build"])  # how it ran is not part of the bytes


def test_index_rows_match_zarr_rows_and_depth_is_aligned(built: Path, sim_recordings: Path
                                                         ) -> None:
    import zarr

    from vtsbench.dataset.build.shard import _calibration, depth_and_contact
    from vtsbench.dataset.format.arrays import depth_to_int16
    from vtsbench.dataset.format.index import read_metas as read_index
    from vtsbench.dataset.format.provenance import sha256_file
    from vtsbench.recordings.media import read_frames

    cal_path = sim_recordings / "calibration.safetensors"
    cal = _calibration(str(cal_path), sha256_file(cal_path))
    for kind in ("static", "slip"):
        metas = read_index(built / "index" / f"{kind}.parquet", kind)
        group = zarr.open_group(str(built / "data" / f"{kind}.zarr"), mode="r")
        rgb, depth, contact = group["rgb"], group["depth"], group["contact"]
        assert [m.row for m in metas] == list(range(rgb.shape[0]))
        assert depth.shape == rgb.shape[:-1] == contact.shape
        for m in metas:
            path, a, b = _source(m.source)
            frames = read_frames(sim_recordings / path, a, b)
            x = rgb[m.row]
            assert np.array_equal(x, frames if kind == "slip" else frames[0]), m.sample_id
        # depth frame t is the depth of RGB frame t: recompute one sample from its own frames
        r = len(metas) - 1
        x = rgb[r] if kind == "slip" else rgb[r][None]
        d, c = depth_and_contact(x, cal, "dct")
        got = depth[r] if kind == "slip" else depth[r][None]
        assert np.array_equal(depth_to_int16(d), got)
        assert np.array_equal(c, contact[r] if kind == "slip" else contact[r][None])
    slip = read_index(built / "index" / "slip.parquet", "slip")
    assert all(m.direction is None for m in slip if m.state != "slip")
    info = json.loads((built / "meta/info.json").read_text())
    assert [m.class_idx for m in slip] == [info["objects"].index(m.object) for m in slip]


def test_info_command(built: Path) -> None:
    res = CliRunner().invoke(app, ["info", str(built)], terminal_width=160)
    assert res.exit_code == 0, res.output
    for text in ("samples per object", "slip directions", "unseen_objects", "on disk",
                 "dataset_sha256", "1.0.0"):
        assert text in res.output
    # at 80 columns (a pipe's default) no header, object or direction name is cut or cropped
    res = CliRunner().invoke(app, ["info", str(built)], env={"COLUMNS": "80"}, terminal_width=80)
    assert res.exit_code == 0 and "…" not in res.output, res.output
    assert all(len(ln) <= 80 for ln in res.output.splitlines()), res.output
    info = json.loads((built / "meta/info.json").read_text())
    for name in (*info["objects"], "down-right", "unknown"):
        assert f"│ {name} " in res.output, name


def test_loads_with_datasets_offline(built: Path, tmp_path: Path) -> None:
    code = (
        "import sys, datasets\n"
        "root, cache = sys.argv[1], sys.argv[2]\n"
        "d = datasets.load_dataset(root, cache_dir=cache)\n"
        "print('default', list(d), d['index'].num_rows, d['index'][0]['sample_id'])\n"
        "s = datasets.load_dataset(root, 'static', cache_dir=cache)['index']\n"
        "print('static', s.num_rows)\n"
        "p = datasets.load_dataset(root, 'preview_slip', cache_dir=cache)['preview']\n"
        "x = p[0]\n"
        "print('preview_slip', p.num_rows, len(x['rgb']), x['rgb'][0].size, x['rgb'][0].mode,"
        " x['depth'][0].mode)\n"
        "q = datasets.load_dataset(root, 'preview_static', cache_dir=cache)['preview']\n"
        "print('preview_static', q.num_rows, q[0]['contact'].mode)\n")
    env = {**os.environ, "HF_DATASETS_OFFLINE": "1", "HF_HUB_OFFLINE": "1",
           "HF_HOME": str(tmp_path / "hf")}
    res = subprocess.run([sys.executable, "-c", code, str(built), str(tmp_path / "cache")],
                         capture_output=True, text=True, env=env, timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    out = res.stdout
    assert "default ['index'] 9 seq-00001" in out
    assert "static 6" in out
    assert "preview_slip 4 8 (128, 96) RGB RGB" in out
    assert "preview_static 6 L" in out


def test_refuses_to_overwrite(built: Path, sim_recordings: Path, tmp_path: Path) -> None:
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "keep.txt").write_text("mine")
    for extra in ((), ("--overwrite",)):  # not a dataset: refused even with --overwrite
        res = CliRunner().invoke(app, ["build", str(sim_recordings), str(mine), *BUILD_ARGS,
                                       *extra])
        assert res.exit_code == 2
        assert ("not a vtsbench dataset" if extra else "already exists (use --overwrite") \
            in res.output
    assert (mine / "keep.txt").read_text() == "mine"
    res = CliRunner().invoke(app, ["build", str(sim_recordings), str(sim_recordings.parent),
                                   "--overwrite"])
    assert res.exit_code == 2 and "the recordings folder is inside OUT" in res.output
    out = Path(shutil.copytree(built, tmp_path / "ds"))
    (out / "README.md").write_text("old")
    res = cli("build", str(sim_recordings), str(out), *BUILD_ARGS, "--overwrite")
    assert res.returncode == 0, res.stderr
    assert tree_bytes(out) == tree_bytes(built)  # a CLI build equals the in-process one
    assert not any(p.name.startswith(".ds") for p in tmp_path.iterdir())


def test_missing_calibration_says_how_to_make_one(sim_recordings: Path, tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["build", str(sim_recordings), str(tmp_path / "ds"),
                                   "--calibration", str(tmp_path / "none.safetensors")])
    assert res.exit_code == 2 and "calibration file not found" in res.output
    from tests.fixtures.recordings import copy_recordings

    rec = copy_recordings(sim_recordings, tmp_path / "rec")
    (rec / "calibration.safetensors").unlink()
    res = CliRunner().invoke(app, ["build", str(rec), str(tmp_path / "ds")])
    assert res.exit_code == 2
    assert "vtsbench calibrate" in res.output and len(res.output.strip().splitlines()) == 1
    assert "--no-depth" in res.output
    assert not (tmp_path / "ds").exists()


@pytest.mark.parametrize("cmd", ["build", "info", "verify"])
def test_help(cmd: str) -> None:
    res = CliRunner().invoke(app, [cmd, "--help"])
    assert res.exit_code == 0 and "Usage" in res.output
