"""Splits a lab gives: a list of held-out objects (`given_objects`) or whole split files.

`vtsbench build --holdout-objects FILE` makes the scheme `given_objects`, whose test part is
exactly the listed objects' samples and whose validation part is whole objects drawn (seeded)
from the rest; `--split-file FILE` adds a scheme written in schemas/split.schema.json. Both are
leak-checked with the built-in schemes before any frame is converted. The same rule over whole
episodes (`objects_split`) is splits/episodes.py's `given_objects_episodes`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from ...errors import VtsError
from ...jsonio import read_bytes
from ..format.layout import KINDS
from ..format.records import SampleMeta, SplitFile, schema_errors
from .leaks import leak_check
from .schemes import SCHEMES, rng_for

GIVEN = "given_objects"
#: Largest object list or split file read (bytes): a list of object names is small.
MAX_FILE_BYTES = 64 << 20


def _read_text(path: Path, what: str) -> str:
    """A small UTF-8 text file; a folder, a FIFO, a device or a missing file is refused for
    what it is (one line)."""
    try:
        return read_bytes(path, what, MAX_FILE_BYTES).decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise VtsError(f"not UTF-8 text ({e.reason})", path) from None


def read_object_list(path: str | Path) -> list[str]:
    """Object names, one a line; blank lines and lines starting with '#' are skipped."""
    path = Path(path)
    names = [ln.strip() for ln in _read_text(path, "file of object names").splitlines()]
    names = [n for n in names if n and not n.startswith("#")]
    if not names:
        raise VtsError("lists no object (one object name a line)", path)
    return check_object_list(names, path)


def check_object_list(names: Any, source: str | Path | None = None) -> list[str]:
    """A list of held-out object names: non-empty text, none with control characters, none
    twice (one line naming the first bad one; `source` the file or call it came from)."""
    if isinstance(names, str) or not isinstance(names, Sequence) or not names:
        raise VtsError(f"{GIVEN}: the held-out objects must be a non-empty list of object "
                       f"names, got {names!r:.80}", source)
    names = list(names)
    at = next((i for i, n in enumerate(names) if not isinstance(n, str) or not n.strip()), None)
    if at is not None:
        raise VtsError(f"{GIVEN}: object name {names[at]!r:.80} is not a non-empty text", source)
    bad = next((n for n in names if any(ord(c) < 32 for c in n)), None)
    if bad is not None:
        raise VtsError(f"object name {bad!r} holds control characters", source)
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup is not None:
        raise VtsError(f"object {dup!r} listed twice", source)
    return names


def given_objects_split(samples: Iterable[SampleMeta], held_out: Sequence[str], *,
                        seed: int = 0, val_fraction: float = 0.1,
                        source: str = "") -> SplitFile:
    """Test: every sample of the given objects; val: whole objects drawn from the rest (a
    val_fraction of them, rounded, at least one when three or more remain); train: the others.

    The samples' kind is slip when any slip sample exists, else static. A listed object found
    in no sample is an error naming it, as is a list that leaves no object to train on."""
    ss = sorted(samples, key=lambda s: s.sample_id)
    kind = "slip" if any(s.kind == "slip" for s in ss) else "static"
    return objects_split([(s.sample_id, s.object) for s in ss if s.kind == kind], held_out,
                         kind=kind, what=f"{kind} sample", seed=seed,
                         val_fraction=val_fraction, source=source)


def objects_split(items: Sequence[tuple[str, str]], held_out: Sequence[str], *, kind: str,
                  what: str, seed: int = 0, val_fraction: float = 0.1,
                  source: str = "") -> SplitFile:
    """The given_objects rule over (id, object) pairs of one kind (samples or episodes, named
    `what` in the errors): test every id of the listed objects, val whole objects drawn seeded
    from the rest, train the others; the same objects and seed give the same parts."""
    if not items:
        raise VtsError(f"{GIVEN}: no {what}s", source or None)
    objects = sorted({o for _, o in items})
    missing = [o for o in held_out if o not in objects]
    if missing:
        near = [o for o in objects if any(m.lower() == o.lower() for m in missing)]
        hint = f" (differs in case from {', '.join(near)})" if near else ""
        raise VtsError(f"{GIVEN}: {len(missing)} listed object(s) have no {what}, first "
                       f"{missing[0]!r}{hint}; the dataset's objects: "
                       f"{', '.join(objects[:12])}{', ...' if len(objects) > 12 else ''}",
                       source or None)
    test_objs = sorted(set(held_out))
    rest = [o for o in objects if o not in test_objs]
    if not rest:
        raise VtsError(f"{GIVEN}: the list holds out every object; none is left to train on",
                       source or None)
    n_val = math.floor(val_fraction * len(rest) + 0.5)
    if val_fraction > 0 and len(rest) >= 3:
        n_val = max(1, n_val)
    n_val = min(n_val, len(rest) - 1)
    rng = rng_for(GIVEN, seed)
    val_objs = sorted(rest[i] for i in rng.permutation(len(rest))[:n_val])
    part_of = {o: "test" for o in test_objs} | {o: "val" for o in val_objs}
    parts: dict[str, list[str]] = {"train": [], "val": [], "test": []}
    for i, o in items:
        parts[part_of.get(o, "train")].append(i)
    if not parts["val"]:
        del parts["val"]
    params = {"held_out_objects": test_objs, "val_objects": val_objs,
              "train_objects": [o for o in rest if o not in val_objs],
              "val_fraction": val_fraction, "source": Path(source).name if source else ""}
    desc = (f"the {len(test_objs)} given objects as test; {len(val_objs)} other whole objects "
            f"as val (seeded); train the remaining {len(rest) - len(val_objs)}")
    return SplitFile(GIVEN, kind, desc, seed, parts, ["object"], params)


def read_split_file(path: str | Path) -> SplitFile:
    """A split scheme in schemas/split.schema.json from a user's file; one-line errors."""
    path = Path(path)
    text = _read_text(path, "split file")
    try:
        doc = json.loads(text, parse_constant=_no_constant)
    except json.JSONDecodeError as e:
        raise VtsError(f"invalid JSON at line {e.lineno} column {e.colno}: {e.msg}",
                       path) from None
    except ValueError as e:
        raise VtsError(str(e), path) from None
    errs = schema_errors(doc, "split")
    if errs:
        more = f" (and {len(errs) - 1} more)" if len(errs) > 1 else ""
        raise VtsError(f"not a split file: {errs[0]}{more}", path)
    empty = next((p for p, ids in doc["parts"].items() if not ids), None)
    if empty is not None:  # trains or scores on nothing: refused now, not by a later train
        raise VtsError(f"part {empty!r} lists no sample; remove the part or give it samples",
                       path)
    sp = SplitFile.from_dict(doc)
    if sp.name in (*SCHEMES, GIVEN):
        raise VtsError(f"split name {sp.name!r} is a built-in scheme's; rename it", path)
    return sp


def _no_constant(name: str) -> float:
    raise ValueError(f"{name} is not valid JSON")


def check_given(split: SplitFile, samples: Sequence[SampleMeta], source: str) -> None:
    """Refuse a given split whose parts name samples the build does not make, or that leaks;
    a split of episodes is checked where episodes are built (`--store episodes`)."""
    if split.kind not in KINDS:
        raise VtsError(f"split {split.name!r} is a split of {split.kind}s, not of static or slip "
                       "samples: `vtsbench build --store episodes` takes it", source)
    problems = leak_check(split, samples)
    if problems:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        raise VtsError(f"split {split.name!r} does not fit this build: {problems[0]}{more}",
                       source)
