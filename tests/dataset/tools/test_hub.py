"""`vtsbench export-hf` and `push`: every sample in parquet, read back offline by
`datasets.load_dataset` (and streamed) pixel for pixel, one config per split scheme."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

import vtsbench
from vtsbench.cli import app
from vtsbench.dataset.read.hf import hub_arrays
from vtsbench.dataset.tools.hub_layout import HUB_DIR, config_name, split_name
from vtsbench.dataset.tools.verify import verify
from vtsbench.labels import DIRECTION_NAMES, STATES


@pytest.fixture(scope="module")
def hub_dataset(vts_dataset: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of the test dataset with its hub copy, written through the command."""
    root = Path(shutil.copytree(vts_dataset, tmp_path_factory.mktemp("hub") / "ds"))
    res = CliRunner().invoke(app, ["export-hf", str(root), "--workers", "2", "--license",
                                   "cc-by-4.0", "--quiet"])
    assert res.exit_code == 0, res.output
    assert "slip_unseen_objects" in res.output
    return root


@pytest.fixture
def offline(monkeypatch: pytest.MonkeyPatch) -> None:
    """datasets and huggingface_hub told they are offline (they never reach the network)."""
    import datasets
    import huggingface_hub.constants

    monkeypatch.setattr(datasets.config, "HF_HUB_OFFLINE", True)
    monkeypatch.setattr(huggingface_hub.constants, "HF_HUB_OFFLINE", True)


def card_yaml(root: Path) -> dict:
    text = (root / "README.md").read_text(encoding="utf-8")
    return yaml.safe_load(text.split("---\n")[1])


def expected_configs(ds: vtsbench.VtsDataset) -> dict[str, dict[str, list[str]]]:
    """config -> split -> sample ids, from the split files."""
    out = {}
    for scheme in ds.splits:
        kind = ds.split_file(scheme).kind
        out[config_name(kind, scheme)] = {split_name(p): ds.split(scheme, p).ids
                                          for p in ds.parts(scheme)}
    for kind in ("static", "slip"):
        out[f"{kind}_all"] = {"full": ds.view(kind).ids}
    return out


def test_card_and_verify(hub_dataset: Path) -> None:
    ds = vtsbench.load(hub_dataset)
    meta = card_yaml(hub_dataset)
    assert meta["license"] == "cc-by-4.0" and meta["size_categories"] == ["n<1K"]
    assert "depth-estimation" in meta["task_categories"]
    configs = {c["config_name"]: c for c in meta["configs"]}
    want = expected_configs(ds)
    assert set(want) <= set(configs)
    assert {"slip_unseen_objects", "slip_seen", "slip_object_folds", "static_sessions",
            "static_locations"} <= set(configs)
    assert configs["slip_unseen_objects"].get("default") is True
    assert sum(bool(c.get("default")) for c in configs.values()) == 1
    for name, splits in want.items():
        assert [d["split"] for d in configs[name]["data_files"]] == list(splits)
        for d in configs[name]["data_files"]:
            assert all((hub_dataset / p).is_file() for p in d["path"])
    assert "datasets.load_dataset" in (hub_dataset / "README.md").read_text()
    # every sample once: the files of *_all are all the hub files, and no more
    files = sorted(p.relative_to(hub_dataset).as_posix()
                   for p in (hub_dataset / HUB_DIR).rglob("*.parquet"))
    assert sorted(configs["slip_all"]["data_files"][0]["path"]
                  + configs["static_all"]["data_files"][0]["path"]) == files
    report = verify(hub_dataset)
    assert report.ok, report.problems
    assert all(f in ds.info.files for f in files) and "README.md" in ds.info.files


def test_parquet_files_have_small_row_groups(hub_dataset: Path) -> None:
    import pyarrow.parquet as pq

    for p in (hub_dataset / HUB_DIR).rglob("*.parquet"):
        meta = pq.ParquetFile(p).metadata
        assert all(meta.row_group(i).total_byte_size <= 64 * 2**20
                   for i in range(meta.num_row_groups))
        assert p.stat().st_size < 512 * 2**20


def _check_rows(rows: list[dict], ds: vtsbench.VtsDataset, kind: str) -> None:
    """Rows read by datasets against the loader: labels, exact pixels, depth and contact."""
    import io

    from PIL import Image

    view = ds.view(kind)
    for r in rows:
        s = view.by_id(r["sample_id"])
        frames = r["rgb"] if kind == "slip" else [r["rgb"]]
        assert all(im.format == "TIFF" and im.mode == "RGB" for im in frames)
        got = hub_arrays(r, ds.info.depth_scale_mm)
        assert got["rgb"].dtype == np.uint8 and np.array_equal(got["rgb"], s["rgb"])
        assert got["depth"].dtype == np.float32
        assert np.array_equal(got["depth"], s["depth"])  # lossless: the loader's float32 mm
        assert (s["depth"] < 0).any()  # negative counts survive the uint16 images too
        assert got["contact"].dtype == bool and np.array_equal(got["contact"], s["contact"])
        assert r["object"] == s["class_idx"]
        preview = r["depth_preview"]  # left encoded: {"bytes": PNG, "path": None}
        previews = [Image.open(io.BytesIO(p["bytes"])) for p in
                    (preview if kind == "slip" else [preview])]
        assert all(im.mode == "RGB" and im.size == got["rgb"].shape[-2:-4:-1] for im in previews)
        if kind == "slip":
            assert r["state"] == s["state_idx"] and r["direction"] == s["direction"]


def test_load_dataset_every_config(hub_dataset: Path, tmp_path: Path, offline: None) -> None:
    import datasets

    ds = vtsbench.load(hub_dataset)
    for name, splits in expected_configs(ds).items():
        kind = "slip" if name.startswith("slip") else "static"
        for split, ids in splits.items():
            d = datasets.load_dataset(str(hub_dataset), name, split=split,
                                      cache_dir=str(tmp_path))
            assert sorted(d["sample_id"]) == sorted(ids), (name, split)
            if name.endswith("_all"):
                continue
            feats = d.features
            assert feats["object"].names == ds.info.objects
            if kind == "slip":
                assert feats["state"].names == list(STATES)
                assert feats["direction"].names == list(DIRECTION_NAMES)
            _check_rows([d[0], d[len(d) - 1]], ds, kind)
    whole = datasets.load_dataset(str(hub_dataset), "slip_all", split="full",
                                  cache_dir=str(tmp_path))
    _check_rows(list(whole), ds, "slip")  # every slip sample, pixel for pixel
    rows = whole.with_format("numpy")  # the fast format: arrays, images not widened
    s = ds.slip.by_id(rows[0]["sample_id"])
    for name, dtype in (("rgb", np.uint8), ("depth", np.uint16), ("contact", bool)):
        assert rows[0][name].dtype == dtype and rows[0][name].shape == s[name].shape
    assert np.array_equal(rows[0]["rgb"], s["rgb"])
    assert np.array_equal(rows[0]["contact"], s["contact"])
    mm = rows[0]["depth"].view(np.int16).astype(np.float32) * np.float32(0.001)  # the card's
    assert np.array_equal(mm, s["depth"])


def test_arrow_cache_no_larger_than_the_parquet(hub_dataset: Path, tmp_path: Path,
                                                offline: None) -> None:
    """load_dataset's Arrow cache holds the encoded images, not pixels: no larger than the
    parquet files it was built from (layout 1 expanded depth to 9x its parquet bytes)."""
    import datasets

    meta = {c["config_name"]: c for c in card_yaml(hub_dataset)["configs"]}
    for name in ("slip_all", "static_all"):
        files = meta[name]["data_files"][0]["path"]
        parquet = sum((hub_dataset / f).stat().st_size for f in files)
        cache = tmp_path / name
        d = datasets.load_dataset(str(hub_dataset), name, split="full", cache_dir=str(cache))
        arrow = sum(p.stat().st_size for p in cache.rglob("*.arrow"))
        assert d.num_rows and parquet / 2 < arrow <= parquet, (name, arrow, parquet)


def test_layout_version_and_uncompressed_images(hub_dataset: Path) -> None:
    """The parquet files say their layout version and depth scale; image columns are stored
    as they are (already compressed), the labels with zstd."""
    import json

    import pyarrow.parquet as pq

    from vtsbench.dataset.tools.hub_rows import HUB_VERSION, IMAGE_COLUMNS

    for p in (hub_dataset / HUB_DIR).rglob("*.parquet"):
        f = pq.ParquetFile(p)
        doc = json.loads(f.schema_arrow.metadata[b"vtsbench"])
        assert doc == {"hub_version": HUB_VERSION, "depth_scale_mm": 0.001}
        assert f.schema_arrow.field("depth").metadata[b"units"] == b"count"
        rg = f.metadata.row_group(0)
        for c in range(rg.num_columns):
            col = rg.column(c)
            top = col.path_in_schema.split(".")[0]
            want = "UNCOMPRESSED" if top in IMAGE_COLUMNS else "ZSTD"
            assert col.compression == want, (col.path_in_schema, col.compression)
    assert f"Layout version\n{HUB_VERSION}" in (hub_dataset / "README.md").read_text()


def test_tiffs_read_back_and_a_pillow_without_zstd_is_one_line(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The TIFFs written by hand decode with Pillow, exactly and the same bytes each time; a
    Pillow that cannot read them stops export-hf in one line, before anything is written."""
    import io

    from PIL import Image

    from vtsbench.dataset.tools.hub_rows import check_codecs, tiff
    from vtsbench.errors import VtsError

    rng = np.random.default_rng(0)
    for a, predictor in ((rng.integers(0, 256, (5, 7, 3), dtype=np.uint8), True),
                         (rng.integers(0, 2**16, (5, 7), dtype=np.uint16), False),
                         (rng.integers(0, 2**16, (1, 1), dtype=np.uint16), True)):
        data = tiff(a, predictor)
        assert data == tiff(a, predictor) and data[:4] == b"II*\x00"
        assert np.array_equal(np.asarray(Image.open(io.BytesIO(data))), a)
    check_codecs()

    def no_zstd(*_a: object, **_k: object) -> None:
        raise OSError("decoder zstd not available")

    monkeypatch.setattr(Image, "open", no_zstd)
    with pytest.raises(VtsError, match="cannot read them") as e:
        check_codecs()
    assert "\n" not in str(e.value) and "pip install" in str(e.value)


@pytest.mark.parametrize("scale", [0.001, 0.002, 0.00037])
def test_stored_counts_are_exact_for_every_count(scale: float) -> None:
    """The export writes the stored counts back from the loader's mm, at any depth scale."""
    from vtsbench.dataset.format.arrays import depth_to_mm
    from vtsbench.dataset.tools.hub_rows import stored_counts

    counts = np.arange(-32768, 32768).astype(np.int16)
    mm = depth_to_mm(counts) * np.float32(scale / 0.001)  # as the loader scales it
    assert np.array_equal(stored_counts(mm, scale), counts)
    assert np.array_equal(hub_arrays({"depth": counts.view(np.uint16)}, scale)["depth"], mm)


def test_hub_arrays_reads_both_layouts() -> None:
    """hub_arrays: counts as uint16 bits (layout 2) or mm (layout 1), PIL or numpy rows."""
    from PIL import Image

    counts = np.array([[[-5, 0], [7, 32767]]], np.int16)
    mm = counts.astype(np.float32) * np.float32(0.001)
    rgb = np.arange(12, dtype=np.uint8).reshape(1, 2, 2, 3)
    v2 = {"rgb": [Image.fromarray(rgb[0])], "depth": [Image.fromarray(counts[0].view(np.uint16))],
          "contact": np.ones((1, 2, 2), bool)}
    got = hub_arrays(v2)
    assert np.array_equal(got["rgb"], rgb) and np.array_equal(got["depth"], mm)
    assert got["depth"].dtype == np.float32 and got["contact"].dtype == bool
    assert np.array_equal(hub_arrays({"depth": mm.tolist()})["depth"], mm)  # layout 1: mm
    assert np.array_equal(hub_arrays({"depth": counts.view(np.uint16)}, 0.002)["depth"],
                          mm * np.float32(2))


def test_streaming(hub_dataset: Path, offline: None) -> None:
    import datasets

    ds = vtsbench.load(hub_dataset)
    for name, splits in expected_configs(ds).items():
        kind = "slip" if name.startswith("slip") else "static"
        for split, ids in splits.items():
            it = datasets.load_dataset(str(hub_dataset), name, split=split, streaming=True)
            rows = list(it)
            assert sorted(r["sample_id"] for r in rows) == sorted(ids)
            _check_rows(rows[:1], ds, kind)


def test_rgb_only_dataset_exports(tmp_path: Path, offline: None) -> None:
    import datasets

    from tests.fixtures.datasets import SIZE
    from vtsbench.dataset.build import BuildOptions, build
    from vtsbench.dataset.tools.hub import export_hf
    from vtsbench.sim.simulate import simulate

    simulate(tmp_path / "rec", seed=1, n_static=4, n_sequences=4, n_presses=0, size=SIZE,
             progress=False)
    build(tmp_path / "rec", tmp_path / "ds", BuildOptions(depth=False))
    export_hf(tmp_path / "ds")
    d = datasets.load_dataset(str(tmp_path / "ds"), "static_all", split="full",
                              cache_dir=str(tmp_path / "c"))
    assert "depth" not in d.column_names and "depth_preview" not in d.column_names
    s = vtsbench.load(tmp_path / "ds").static.by_id(d[0]["sample_id"])
    assert np.array_equal(np.asarray(d[0]["rgb"]), s["rgb"])
    assert set(hub_arrays(d.with_format("numpy")[0])) == {"rgb"}
    assert verify(tmp_path / "ds").ok


def test_export_errors_are_one_line(vts_dataset: Path, tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["export-hf", str(tmp_path / "none")])
    assert res.exit_code == 2 and "no such dataset folder" in res.output
    res = CliRunner().invoke(app, ["export-hf", str(vts_dataset), "--license", "MIT\nx: 1"])
    assert res.exit_code == 2 and "license must be" in res.output
    assert len(res.output.strip().splitlines()) == 1


def test_push_dry_run_lists_files(hub_dataset: Path) -> None:
    res = CliRunner().invoke(app, ["push", str(hub_dataset), "me/tactile", "--dry-run"],
                             terminal_width=200)
    assert res.exit_code == 0, res.output
    for rel in ("README.md", "meta/info.json", "index/slip.parquet", "hf/slip/000-000.parquet",
                "data/slip.zarr/zarr.json"):
        assert rel in res.output
    assert "dry run: would upload" in res.output and "datasets/me/tactile" in res.output
    res = CliRunner().invoke(app, ["push", str(hub_dataset), "me/tactile", "--dry-run",
                                   "--no-zarr"], terminal_width=200)
    assert res.exit_code == 0 and "data/slip.zarr" not in res.output
    assert "leaving out" in res.output


def test_push_uploads_through_huggingface_hub(hub_dataset: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """The upload's calls, recorded by a stand-in for HfApi (nothing leaves the machine)."""
    import huggingface_hub

    calls: list[tuple[str, dict]] = []

    class FakeApi:
        def create_repo(self, repo_id: str, **kw: object) -> None:
            calls.append(("create_repo", {"repo_id": repo_id, **kw}))

        def upload_folder(self, **kw: object) -> str:
            calls.append(("upload_folder", dict(kw)))
            return "https://hub.example/commit/1"

    monkeypatch.setattr(huggingface_hub, "HfApi", FakeApi)
    res = CliRunner().invoke(app, ["push", str(hub_dataset), "me/tactile", "--private"])
    assert res.exit_code == 0, res.output
    assert calls[0] == ("create_repo", {"repo_id": "me/tactile", "repo_type": "dataset",
                                        "private": True, "exist_ok": True})
    up = calls[1][1]
    assert up["folder_path"] == str(hub_dataset) and up["repo_type"] == "dataset"
    assert "data/**" not in up["ignore_patterns"] and "https://hub.example" in res.output


def test_push_refuses_a_damaged_dataset(hub_dataset: Path, tmp_path: Path) -> None:
    bad = Path(shutil.copytree(hub_dataset, tmp_path / "bad"))
    target = next((bad / HUB_DIR / "slip").glob("*.parquet"))
    target.write_bytes(target.read_bytes()[:-10])
    res = CliRunner().invoke(app, ["push", str(bad), "me/tactile", "--dry-run"])
    assert res.exit_code == 2 and "does not verify" in res.output
