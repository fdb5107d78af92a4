"""Outputs that replace a good copy keep it until the new one is complete, at every kill point.

`build --overwrite` and `export-hf` are killed, deterministically, before each operation that
changes files (os.replace, os.rename, shutil.rmtree, the renameat2 exchange, a parquet row
group): from that operation on every change to the disk fails, as after SIGKILL, so not even
the cleanup handlers can touch the files. Then the output must be a complete copy, the
previous one or the new one (`verify` passes), and a rerun must finish without redoing the
work already done and leave nothing beside it. Both with the one-step exchange and with the
two renames used where it is missing (another OS or filesystem).
"""

from __future__ import annotations

import dataclasses
import gc
import os
import shutil
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from vtsbench import atomic
from vtsbench.dataset.build import BuildOptions, build, staging
from vtsbench.dataset.build import finish as finish_mod
from vtsbench.dataset.build import pipeline as build_mod
from vtsbench.dataset.format.info import load_info
from vtsbench.dataset.tools import hub
from vtsbench.dataset.tools.verify import verify
from vtsbench.errors import VtsError

MODES = ("exchange", "two renames")


class Kill(BaseException):
    """Stands for the process being killed at this point."""


class Faults:
    """Kills at the `at`-th file operation once armed: that operation and every later change
    to the disk raise Kill. `seen` names the operations passed, in order, `point` the one
    killed."""

    COUNTED = ((os, "replace"), (os, "rename"), (shutil, "rmtree"), (atomic, "exchange"))
    BLOCKED = ((os, "unlink"), (os, "remove"), (os, "rmdir"), (os, "link"), (os, "mkdir"))

    def __init__(self, mp: pytest.MonkeyPatch, at: int | None, mode: str) -> None:
        import pyarrow.parquet as pq

        self.at, self.armed, self.dead, self.seen = at, False, False, []
        self.point = "(end: not killed)"
        if mode == "two renames":  # a system or filesystem without the one-step exchange
            mp.setattr(atomic, "exchange", lambda _a, _b: False)
        for owner, name in self.COUNTED:
            mp.setattr(owner, name, self._wrap(getattr(owner, name), name, True))
        for owner, name in self.BLOCKED:
            mp.setattr(owner, name, self._wrap(getattr(owner, name), name, False))
        mp.setattr(pq.ParquetWriter, "write_table",
                   self._wrap(pq.ParquetWriter.write_table, "write_table", True))

    def _wrap(self, fn: Callable[..., Any], name: str, counted: bool) -> Callable[..., Any]:
        def op(*args: Any, **kwargs: Any) -> Any:
            if self.dead:
                raise Kill(name)
            if self.armed and counted:
                where = next((Path(a).name for a in args if isinstance(a, str | Path)), "")
                if len(self.seen) == self.at:
                    self.dead, self.point = True, f"{len(self.seen)}: {name}({where})"
                    raise Kill(self.point)
                self.seen.append(f"{name}({where})")
            return fn(*args, **kwargs)

        return op

    @contextmanager
    def arm(self) -> Iterator[None]:
        self.armed = True
        try:
            yield
        finally:
            self.armed = False

    def run(self, fn: Callable[[], Any]) -> bool:
        """Run fn; True when it was killed. The disk works again afterwards."""
        gc.freeze()  # the collection below looks only at what fn made: 0.12 -> 0.01 s a run
        try:
            fn()
            return False
        except Kill:
            return True
        finally:
            self.dead = self.armed = False
            gc.collect()  # files the dead process held (its lock) are closed, as by the kernel
            gc.unfreeze()


def _arm_at(mp: pytest.MonkeyPatch, faults: Faults, owner: Any, name: str) -> None:
    """Arm the faults when owner.name is called (the phase under test starts there)."""
    fn = getattr(owner, name)

    def armed(*args: Any, **kwargs: Any) -> Any:
        with faults.arm():
            return fn(*args, **kwargs)

    mp.setattr(owner, name, armed)


def _beside(out: Path) -> list[str]:
    return sorted(os.listdir(out.parent))


def _info(root: Path) -> Any:
    return load_info(root / "meta" / "info.json")


def _sha(path: Path) -> str:
    return _info(path).dataset_sha256


# -- build --overwrite ---------------------------------------------------------------------

OLD = BuildOptions(depth=False, shard_mb=0.01, progress=False, seed=1)
NEW = BuildOptions(depth=False, shard_mb=0.01, progress=False, seed=2, overwrite=True)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """Recordings (no calibration), the reference new dataset's checksum, and a folder holding
    an old dataset `ds` beside the complete partial build of the new one (killed just before
    its finish): the state every case starts from."""
    from vtsbench.sim.simulate import simulate

    base = tmp_path_factory.mktemp("kill")
    rec = base / "rec"
    simulate(rec, seed=1, n_static=4, n_sequences=4, n_presses=0, size=(32, 48),
             progress=False)
    new = build(rec, base / "new" / "ds", NEW)
    start = base / "start" / "ds"
    build(rec, start, OLD)
    mp = pytest.MonkeyPatch()
    try:
        def killed(*_a: Any, **_k: Any) -> None:
            raise Kill("finish")

        mp.setattr(build_mod, "finish", killed)
        with pytest.raises(Kill):
            build(rec, start, NEW)
    finally:
        mp.undo()
    assert staging.partial_path(start).is_dir()
    assert _sha(start) != _sha(new.out)
    return {"rec": rec, "start": start, "old": _sha(start), "new": _sha(new.out),
            "shards": sum(new.shards.values())}


def _build_case(tiny: dict[str, Any], tmp: Path, mp: pytest.MonkeyPatch, at: int | None,
                mode: str) -> tuple[bool, Faults, Path]:
    out = Path(shutil.copytree(tiny["start"].parent, tmp / "case", symlinks=True)) / "ds"
    faults = Faults(mp, at, mode)
    owner, name = (finish_mod, "commit") if mode == "two renames" else (build_mod, "finish")
    _arm_at(mp, faults, owner, name)
    return faults.run(lambda: build(tiny["rec"], out, NEW)), faults, out


@pytest.mark.parametrize("mode", MODES)
def test_build_overwrite_killed_at_every_point(tiny: dict[str, Any], tmp_path: Path,
                                               mode: str) -> None:
    """At each kill point OUT is the old or the new complete dataset (or, with two renames
    between them, the old one complete beside it and put back by the rerun); the rerun keeps
    every shard or, when the swap had happened, leaves the new dataset and nothing beside."""
    at, states = 0, []
    while True:
        with pytest.MonkeyPatch.context() as mp:
            killed, faults, out = _build_case(tiny, tmp_path / str(at), mp, at, mode)
        point = faults.point
        if out.exists():
            assert verify(out).ok, point
            state = {tiny["old"]: "old", tiny["new"]: "new"}[_sha(out)]
        else:  # between the two renames: the old copy, complete, waits beside
            assert mode == "two renames", point
            olds = list(out.parent.glob(".ds.old-*"))
            assert len(olds) == 1 and _sha(olds[0]) == tiny["old"], point
            state = "missing"
        if state == "new":  # finished: a rerun without --overwrite refuses, cleans up
            with pytest.raises(VtsError, match="already exists"):
                build(tiny["rec"], out, dataclasses.replace(NEW, overwrite=False))
        else:
            res = build(tiny["rec"], out, NEW)
            assert (res.shards_built, res.shards_kept) == (0, tiny["shards"]), point
        assert _sha(out) == tiny["new"] and verify(out).ok, point
        assert _beside(out) == ["ds"], point
        states.append((point, state))
        if not killed:
            break
        at += 1
    assert len(states) >= 8
    assert {s for _, s in states} >= {"old", "new"}
    assert ("missing" in {s for _, s in states}) == (mode == "two renames")


def test_build_killed_at_its_final_rename_keeps_every_shard(tiny: dict[str, Any],
                                                            tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch
                                                            ) -> None:
    """A first build (no OUT yet) killed at the rename of its partial folder to OUT: the
    rerun finishes without redoing a shard."""
    out = Path(shutil.copytree(staging.partial_path(tiny["start"]),
                               tmp_path / ".ds.partial")).with_name("ds")
    faults = Faults(monkeypatch, 0, "exchange")
    rename = atomic.replace_dir

    def replace_dir(stage: Path, dst: Path) -> None:
        with faults.arm():
            rename(stage, dst)

    monkeypatch.setattr(atomic, "replace_dir", replace_dir)
    assert faults.run(lambda: build(tiny["rec"], out, NEW))
    assert faults.seen == [] and not out.exists()
    monkeypatch.undo()
    res = build(tiny["rec"], out, NEW)
    assert (res.shards_built, res.shards_kept) == (0, tiny["shards"])
    assert verify(out).ok and _beside(out) == ["ds"]


def test_two_renames_recovered_by_any_later_write(tmp_path: Path) -> None:
    """A staged output (simulate, collect) left missing between the two renames by a killed
    process is put back by the next write of that name; an old copy beside a present output
    is deleted; a running process's copy is left alone."""
    out = tmp_path / "rec"
    (tmp_path / ".rec.old-999999999-abc123").mkdir()
    (tmp_path / ".rec.old-999999999-abc123" / "recordings.json").write_text("{}")
    with pytest.raises(VtsError, match="already exists"), \
            atomic.staged_dir(out, marker="recordings.json"):
        pass
    assert (out / "recordings.json").is_file() and _beside(out) == ["rec"]
    (tmp_path / ".rec.old-999999999-abc124").mkdir()
    live = tmp_path / f".rec.old-{os.getppid()}-abc125"
    live.mkdir()
    atomic.recover_dir(out, "recordings.json")
    assert _beside(out) == [live.name, "rec"]


# -- export-hf -----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def exported(tiny: dict[str, Any], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The old dataset with a hub copy made under another license (README differs)."""
    root = Path(shutil.copytree(tiny["start"], tmp_path_factory.mktemp("exp") / "ds"))
    hub.export_hf(root, license="mit")
    return root


def _license(root: Path) -> str:
    text = (root / "README.md").read_text(encoding="utf-8")
    return "new" if "license: cc-by-4.0" in text else "old" if "license: mit" in text else "?"


def _written(mp: pytest.MonkeyPatch) -> list[str]:
    """Names of the parquet files opened for writing from now on."""
    import pyarrow.parquet as pq

    names: list[str] = []
    init = pq.ParquetWriter.__init__

    def counting(self: Any, where: Any, *args: Any, **kwargs: Any) -> None:
        where = Path(where)  # hf/KIND/.NAME.tmp: named as its done marker
        names.append(f"hf~{where.parent.name}~{where.name[1:].removesuffix('.tmp')}.json")
        init(self, where, *args, **kwargs)

    mp.setattr(pq.ParquetWriter, "__init__", counting)
    return names


@pytest.mark.parametrize("mode", MODES)
def test_export_killed_at_every_point(exported: Path, tmp_path: Path, mode: str) -> None:
    """At each kill point the dataset is the previous complete export or the new one (verify
    passes: every file info.json lists is there, nothing else), and the rerun rewrites only
    the parquet files not yet finished, then leaves nothing beside the dataset."""
    at, states, total = 0, [], len(list(exported.glob("hf/*/*.parquet")))
    while True:
        root = Path(shutil.copytree(exported, tmp_path / str(at) / "ds"))
        with pytest.MonkeyPatch.context() as mp:
            faults = Faults(mp, at, mode)
            owner, name = (staging, "commit") if mode == "two renames" else (hub, "export_hf")
            _arm_at(mp, faults, owner, name)
            killed = faults.run(lambda root=root: hub.export_hf(root, license="cc-by-4.0"))
        point = faults.point
        if root.exists():
            report = verify(root)
            assert report.ok, (point, report.problems)
            state = _license(root)
        else:
            assert mode == "two renames", point
            (old,) = root.parent.glob(".ds.old-*")
            assert verify(old).ok and _license(old) == "old", point
            state = "missing"
        done = {p.name for pattern in (".ds.hf.partial/.export/done/*.json",
                                       ".ds.hf.partial.export/done/*.json")
                for p in root.parent.glob(pattern)}
        with pytest.MonkeyPatch.context() as mp:
            written = _written(mp)
            hub.export_hf(root, license="cc-by-4.0")
        assert verify(root).ok and _license(root) == "new", point
        assert _beside(root) == ["ds"], point
        if state in ("old", "missing"):
            assert len(written) == total - len(done), point
            assert not set(written) & done, point
        states.append((point, state, len(done)))
        if not killed:
            break
        at += 1
    assert {s for _, s, _ in states} >= {"old", "new"}
    if mode == "exchange":
        assert max(n for _, _, n in states) == total  # some kills came with every file done
        assert any(0 < n < total for _, _, n in states)


def test_export_kill_leaves_a_dataset_datasets_can_load(exported: Path, tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch
                                                        ) -> None:
    """Killed after some parquet files were finished, the dataset still loads with
    `datasets.load_dataset` (its previous hub copy), and every hf file info.json lists exists."""
    import datasets

    root = Path(shutil.copytree(exported, tmp_path / "ds"))
    faults = Faults(monkeypatch, 5, "exchange")
    _arm_at(monkeypatch, faults, hub, "export_hf")
    assert faults.run(lambda: hub.export_hf(root, license="cc-by-4.0"))
    monkeypatch.undo()
    assert any(root.parent.glob(".ds.hf.partial/hf/*/*.parquet"))
    info = _info(root)
    assert all((root / rel).is_file() for rel in info.files if rel.startswith("hf/"))
    monkeypatch.setattr(datasets.config, "HF_HUB_OFFLINE", True)
    d = datasets.load_dataset(str(root), "static_all", split="full",
                              cache_dir=str(tmp_path / "cache"))
    assert len(d) == 4


def test_export_disk_full_is_one_line_and_resumes(exported: Path, tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """A full disk while a parquet file is written: one line naming that file, no temporary
    file anywhere, the dataset untouched; the rerun keeps the files finished before."""
    import errno

    import pyarrow.parquet as pq
    from typer.testing import CliRunner

    from vtsbench.cli import app

    root = Path(shutil.copytree(exported, tmp_path / "ds"))
    before = _info(root).to_json()
    write = pq.ParquetWriter.write_table
    calls = []

    def full(self: Any, *args: Any, **kwargs: Any) -> None:
        calls.append(1)
        if len(calls) == 3:
            raise OSError(f"[Errno {errno.ENOSPC}] Error writing bytes to file. Detail: "
                          f"[errno {errno.ENOSPC}] No space left on device")
        write(self, *args, **kwargs)

    monkeypatch.setattr(pq.ParquetWriter, "write_table", full)
    res = CliRunner().invoke(app, ["export-hf", str(root), "--quiet"])
    assert res.exit_code == 2
    lines = res.output.strip().splitlines()
    assert len(lines) == 1, res.output
    assert lines[0].startswith(f"error: {root}/hf/"), lines[0]
    assert ".parquet: cannot write (No space left on device)" in lines[0], lines[0]
    assert "Errno" not in lines[0] and ".tmp" not in lines[0]
    assert not [p for p in tmp_path.rglob("*") if p.name.endswith(atomic.TMP_SUFFIX)]
    assert _info(root).to_json() == before and verify(root).ok
    monkeypatch.undo()
    with pytest.MonkeyPatch.context() as mp:
        written = _written(mp)
        hub.export_hf(root, license="unknown")
    assert verify(root).ok and _beside(root) == ["ds"]
    assert 0 < len(written) == len(list(root.glob("hf/*/*.parquet"))) - 2


# -- leaderboard render ----------------------------------------------------------------------


def test_leaderboard_render_killed_at_every_point(tmp_path: Path) -> None:
    """Each rendered leaderboard.md is replaced in one rename: at every kill point each file is
    its previous text or its new text, whole; the rerun renders them all."""
    from vtsbench.evaluation import leaderboard

    src = Path(leaderboard.__file__).parents[2] / "leaderboards"
    if not any(src.glob("*/*/*.json")):
        pytest.skip("no committed leaderboard entries")
    at = 0
    while True:
        root = Path(shutil.copytree(src, tmp_path / str(at)))
        pages = [f / "leaderboard.md" for f in leaderboard.split_folders(root)]
        for p in pages:
            p.write_text("previous\n")
        new = {p: leaderboard.render_folder(p.parent) for p in pages}
        with pytest.MonkeyPatch.context() as mp:
            faults = Faults(mp, at, "exchange")
            _arm_at(mp, faults, leaderboard, "render")
            killed = faults.run(lambda root=root: leaderboard.render(root))
        texts = [p.read_text() for p in pages]
        assert all(t in ("previous\n", new[p]) for p, t in zip(pages, texts, strict=True))
        assert sum(t == new[p] for p, t in zip(pages, texts, strict=True)) == min(at, len(pages))
        leaderboard.render(root)
        assert all(p.read_text() == new[p] for p in pages)
        if not killed:
            break
        at += 1
    assert at == len(pages) >= 2
