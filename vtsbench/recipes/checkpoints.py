"""Checkpoints as recipes read them: `check_checkpoint` (a file a recipe can open, its header
and metadata parsed through the JSON limits) and `checkpoint_meta` (the metadata of a
safetensors checkpoint a given recipe wrote, read from its header alone)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from vtsbench.errors import VtsError


def check_checkpoint(path: str | Path) -> Path:
    """A checkpoint a recipe can open: a regular file; a .safetensors one whose header and JSON
    metadata values parse (each through the same limits as every user JSON), a .json one that
    parses; else a one-line VtsError. Other formats are the recipe's to read."""
    from vtsbench.jsonio import loads, read_bytes, read_json, regular_file

    path = Path(path)
    if path.suffix == ".json":
        read_json(path, "checkpoint")
    if path.suffix != ".safetensors":
        return regular_file(path, "checkpoint")
    data = read_bytes(path, "checkpoint", 1 << 40)
    n = int.from_bytes(data[:8], "little") if len(data) >= 8 else 0
    if not 0 < n <= len(data) - 8:
        raise VtsError("not a safetensors checkpoint (no header)", path)
    head = loads(data[8:8 + n], path, "checkpoint header")
    if not isinstance(head, dict):
        raise VtsError("not a safetensors checkpoint (header is not a mapping)", path)
    meta = head.get("__metadata__") or {}
    if not isinstance(meta, dict):
        raise VtsError("not a safetensors checkpoint (metadata is not a mapping)", path)
    for key, value in meta.items():
        if isinstance(value, str) and value[:1] in "{[":
            loads(value, path, f"checkpoint metadata {key!r}")
    try:
        from safetensors.numpy import load

        load(data)
    except Exception as e:  # safetensors' own error type for damaged data
        raise VtsError(f"corrupt checkpoint ({str(e).splitlines()[0][:100]})", path) from None
    return path


def checkpoint_meta(path: str | Path, recipe: str, json_keys: Sequence[str] = ()
                    ) -> dict[str, Any]:
    """The metadata of a safetensors checkpoint that RECIPE wrote (only its header is read),
    with JSON_KEYS parsed; any other file (a CSV, another recipe's checkpoint, a damaged
    header) is a one-line VtsError naming it, whatever its suffix."""
    from vtsbench.jsonio import loads, regular_file

    path = regular_file(path, "checkpoint", 1 << 40)
    not_one = VtsError(f"not a {recipe} recipe checkpoint (a safetensors file written by "
                       f"`vtsbench train {recipe}`)", path)
    try:
        with open(path, "rb") as fh:
            n = int.from_bytes(fh.read(8), "little")
            if not 2 <= n <= min(path.stat().st_size - 8, 100 << 20):
                raise not_one
            head = fh.read(n)
    except OSError as e:
        raise VtsError(f"cannot read checkpoint ({e.strerror or e})", path) from None
    if head[:1] != b"{":
        raise not_one
    doc = loads(head, path, "checkpoint header")
    meta = doc.get("__metadata__") if isinstance(doc, dict) else None
    if not isinstance(meta, dict) or meta.get("recipe") != recipe:
        raise not_one
    out: dict[str, Any] = dict(meta)
    for key in json_keys:
        if not isinstance(meta.get(key), str):
            raise VtsError(f"corrupt {recipe} checkpoint (no {key!r} in its metadata)", path)
        out[key] = loads(meta[key], path, f"checkpoint metadata {key!r}")
    return out
