"""The stream header's checkpoint sha256: hashed once for the episodes a submission streams one
after another with one checkpoint, and again once the file changes."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any

import pytest

from tests.fixtures.spy import record_calls
from vtsbench.labels import STATES
from vtsbench.recipes.stream import Source, header, line_errors


class FakeMonitor:
    """What `header` reads of a monitor."""

    def __init__(self, checkpoint: str) -> None:
        self.checkpoint = checkpoint

    def describe(self) -> dict[str, Any]:
        return {"recipe": "flow", "window": 4, "size": None,
                "classes": {"state": list(STATES)}, "fitted_arrays": ["rgb"], "note": "",
                "smoothing": {"rule": "debounce", "calls": 1}}


def test_the_checkpoint_is_hashed_once_per_file(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    import vtsbench.dataset.format.provenance as provenance

    ckpt = tmp_path / "checkpoint.safetensors"
    ckpt.write_bytes(b"weights" * 1000)
    hashed = record_calls(monkeypatch, provenance, "sha256_file")
    monitor = FakeMonitor(str(ckpt))
    heads = [header(monitor, Source("video", f"v{k}.avi", 25.0, lambda: iter(())),
                    realtime=False, device="cpu") for k in range(3)]
    assert len(hashed) == 1
    assert {h["checkpoint_sha256"] for h in heads} == {hashlib.sha256(ckpt.read_bytes())
                                                       .hexdigest()}
    assert not line_errors(heads[0]), line_errors(heads[0])
    ckpt.write_bytes(b"other weights" * 1000)  # retrained in place: hashed again
    st = ckpt.stat()
    os.utime(ckpt, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
    again = header(monitor, Source("video", "v0.avi", 25.0, lambda: iter(())),
                   realtime=False, device="cpu")
    assert len(hashed) == 2
    assert again["checkpoint_sha256"] == hashlib.sha256(ckpt.read_bytes()).hexdigest()
    no_file = header(FakeMonitor(""), Source("video", "v", None, lambda: iter(())),
                     realtime=False, device="cpu")
    assert no_file["checkpoint_sha256"] is None
