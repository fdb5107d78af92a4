"""Files written through `atomic.replacing` get the permissions of an ordinary new file, whatever
mode the library that wrote them chose, unless it chose a wider one."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from vtsbench.atomic import ORDINARY_MODE, replacing, write_bytes_atomic


def _mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def test_the_ordinary_mode_is_what_open_gives(tmp_path: Path) -> None:
    (tmp_path / "plain").write_bytes(b"x")
    assert _mode(tmp_path / "plain") == ORDINARY_MODE
    write_bytes_atomic(tmp_path / "atomic", b"x")
    assert _mode(tmp_path / "atomic") == ORDINARY_MODE


@pytest.mark.parametrize("written", [0o600, 0o400, 0o640])
def test_a_private_file_from_a_library_is_widened(tmp_path: Path, written: int) -> None:
    out = tmp_path / "model.bin"
    with replacing(out) as tmp:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, written)
        os.write(fd, b"weights")
        os.close(fd)
        os.chmod(tmp, written)  # whatever the umask
    assert out.read_bytes() == b"weights"
    assert _mode(out) == ORDINARY_MODE


def test_a_wider_or_executable_mode_is_kept(tmp_path: Path) -> None:
    out = tmp_path / "run.sh"
    with replacing(out) as tmp:
        tmp.write_text("#!/bin/sh\n")
        os.chmod(tmp, 0o755)
    assert _mode(out) == 0o755


def test_a_safetensors_checkpoint_is_readable_by_the_group(tmp_path: Path) -> None:
    torch = pytest.importorskip("torch")
    from safetensors.torch import save_file

    out = tmp_path / "checkpoint.safetensors"
    with replacing(out) as tmp:
        save_file({"w": torch.zeros(2)}, str(tmp))
    assert _mode(out) == ORDINARY_MODE
