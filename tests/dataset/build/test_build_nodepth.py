"""`vtsbench build --no-depth`: an RGB-only dataset from recordings without a calibration, and
what verify, info, the loader, torch and datasets make of it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import vtsbench
from tests.fixtures.datasets import BUILD_ARGS, tree_bytes
from tests.fixtures.recordings import copy_recordings
from vtsbench.cli import app
from vtsbench.errors import VtsError


@pytest.fixture(scope="module")
def rgb_only(sim_recordings: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The simulated recordings without their calibration, built with --no-depth (read-only)."""
    tmp = tmp_path_factory.mktemp("nodepth")
    rec = copy_recordings(sim_recordings, tmp / "rec")
    (rec / "calibration.safetensors").unlink()
    out = tmp / "ds"
    res = CliRunner().invoke(app, ["build", str(rec), str(out), *BUILD_ARGS, "--no-depth"])
    assert res.exit_code == 0, res.output
    return out


def test_layout_info_and_card(rgb_only: Path, built: Path) -> None:
    info = json.loads((rgb_only / "meta" / "info.json").read_text())
    assert info["shapes"] == {"static": {"rgb": [6, 96, 128, 3]},
                              "slip": {"rgb": [9, 8, 96, 128, 3]}}
    assert info["calibration"] is None
    assert info["build"]["arrays"] == ["rgb"]
    assert info["build"]["depth"] is info["build"]["contact"] is info["build"]["solver"] is None
    for kind in ("static", "slip"):
        names = {p.name for p in (rgb_only / "data" / f"{kind}.zarr").iterdir() if p.is_dir()}
        assert names == {"rgb"}
    # the rgb shards are the bytes of the RGB-D build's
    ours, theirs = tree_bytes(rgb_only / "data"), tree_bytes(built / "data")
    rgb = {k: v for k, v in theirs.items() if "/rgb/c/" in k}
    assert rgb and all(ours[k] == v for k, v in rgb.items())
    card = " ".join((rgb_only / "README.md").read_text().split())
    assert "no depth and no contact arrays" in card and "--no-depth" in card
    assert "- rgb-d" not in card


def test_verify_and_info(rgb_only: Path) -> None:
    res = CliRunner().invoke(app, ["verify", str(rgb_only)])
    assert res.exit_code == 0 and "0 problem(s)" in res.output, res.output
    res = CliRunner().invoke(app, ["info", str(rgb_only)], terminal_width=200)
    assert res.exit_code == 0, res.output
    text = " ".join(res.output.split())
    assert "rgb only: no depth or contact" in text and "raw arrays (uint8 RGB)" in text


def test_loader_reads_rgb_and_refuses_depth_in_one_line(rgb_only: Path, built: Path) -> None:
    ds, ref = vtsbench.load(rgb_only), vtsbench.load(built)
    assert ds.arrays == ("rgb",) and ref.arrays == ("rgb", "depth", "contact")
    sample = ds.slip[0]
    assert "depth" not in sample and "contact" not in sample
    assert np.array_equal(sample["rgb"], ref.slip.sample(0, arrays=("rgb",))["rgb"])
    assert [s["sample_id"] for s in ds.static] == ds.static.ids
    assert ds.split("unseen_objects", "test").ids == ref.split("unseen_objects", "test").ids
    for call in (lambda: ds.slip.to_torch("depth"), lambda: ds.static.to_torch("rgbd"),
                 lambda: ds.slip.to_torch("rgb", targets=("contact",)),
                 lambda: ds.slip.read([0], arrays=("rgb", "depth")),
                 lambda: ds.static.by_id(ds.static.ids[0], arrays=("contact",))):
        with pytest.raises(VtsError) as err:
            call()
        msg = str(err.value)
        assert "\n" not in msg and "--no-depth" in msg, msg
    x, target = ds.slip.to_torch("rgb", frames=2)[0]
    assert tuple(x.shape) == (2, 3, 96, 128) and target["sample_id"] == ds.slip.ids[0]


def test_to_hf_holds_rgb_only(rgb_only: Path, tmp_path: Path) -> None:
    hf = vtsbench.load(rgb_only).static.to_hf(copy=True, cache_dir=tmp_path / "hf")
    assert hf.num_rows == 6 and "rgb" in hf.column_names
    assert "depth" not in hf.column_names and "contact" not in hf.column_names


def test_calibration_and_no_depth_exclude_each_other(sim_recordings: Path,
                                                     tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["build", str(sim_recordings), str(tmp_path / "ds"),
                                   "--no-depth", "--calibration",
                                   str(sim_recordings / "calibration.safetensors")])
    assert res.exit_code == 2 and "--no-depth" in res.output
    assert not (tmp_path / "ds").exists()


def test_unknown_scale_and_no_labels(sim_recordings: Path, tmp_path: Path) -> None:
    """Sessions without mm_per_px and entries without labels (as in real recordings)."""
    rec = copy_recordings(sim_recordings, tmp_path / "rec")
    path = rec / "recordings.json"
    doc = json.loads(path.read_text())
    for s in doc["sessions"]:
        s["mm_per_px"] = None
    for e in doc["entries"]:
        e["labels"] = {}
    path.write_text(json.dumps(doc, indent=1))
    out = tmp_path / "ds"
    res = CliRunner().invoke(app, ["build", str(rec), str(out), *BUILD_ARGS, "--no-depth"])
    assert res.exit_code == 0, res.output
    assert CliRunner().invoke(app, ["verify", str(out)]).exit_code == 0
    ds = vtsbench.load(out)
    sample = ds.slip[0]
    assert sample["mm_per_px"] is None and sample["state"] is None
    # what the loader gives fits the sample schema and its typed mirror
    from vtsbench.dataset.format.records import Sample as SampleSpec
    from vtsbench.dataset.format.records import SampleMeta, schema_errors

    for kind in ("static", "slip"):
        s = ds.view(kind)[0]
        assert "depth" not in s and "contact" not in s
        doc = {k: list(v) if isinstance(v, tuple) else v for k, v in s.items() if k != "rgb"}
        doc["rgb"] = {"dtype": str(s["rgb"].dtype), "shape": list(s["rgb"].shape)}
        assert schema_errors(json.loads(json.dumps(doc)), "sample") == [], kind
        row = ds.view(kind).index.to_pylist()[0]
        assert schema_errors({**row, "kind": kind, **({} if kind == "slip" else dict.fromkeys(
            ("state", "state_idx", "direction", "motion_dx_mm", "motion_dy_mm")))},
            "sample", "index_row") == []
        spec = SampleSpec.from_meta(SampleMeta.from_row(row, kind), ds.info.resolution,
                                    ds.info.frames_per_sequence if kind == "slip" else None,
                                    arrays=ds.info.arrays)
        assert spec.to_dict() == doc
    # unlabelled: unseen_objects holds out whole objects without balancing states
    split = ds.split_file("unseen_objects")
    assert split.params["states_unknown"] is True
    held = set(split.params["held_out_objects"])
    assert set(split.parts["test"]) == {i for i, o in zip(ds.slip.ids, ds.slip.index[
        "object"].to_pylist(), strict=True) if o in held}
    assert "object_folds" in ds.splits
    report = json.loads((out / "meta" / "build_report.json").read_text())
    assert "unseen_objects" not in report["splits_skipped"]
    assert "scale unknown" in (out / "README.md").read_text()


def test_no_depth_resumes_a_partial_rgbd_build(sim_recordings: Path, tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    from tests.fixtures.datasets import SHARD_MB
    from vtsbench.dataset.build import BuildOptions, build, partial_path
    from vtsbench.dataset.build import execute as build_mod

    out = tmp_path / "ds"
    real, calls = build_mod.run_shard, []

    def stop(task):
        calls.append(task)
        if len(calls) > 3:
            raise KeyboardInterrupt
        return real(task)

    with monkeypatch.context() as m:
        m.setattr(build_mod, "run_shard", stop)
        with pytest.raises(KeyboardInterrupt):
            build(sim_recordings, out, BuildOptions(shard_mb=SHARD_MB))
    assert (partial_path(out) / "data" / "static.zarr" / "depth").is_dir()
    res = build(sim_recordings, out, BuildOptions(shard_mb=SHARD_MB, depth=False))
    assert res.shards_kept == 0  # other arrays, other bytes: every shard again
    for kind in ("static", "slip"):
        names = {p.name for p in (out / "data" / f"{kind}.zarr").iterdir() if p.is_dir()}
        assert names == {"rgb"}
    assert CliRunner().invoke(app, ["verify", str(out)]).exit_code == 0
