"""Split schemes over episodes (format 1.2): whole episodes held out by object
(`unseen_objects`) or by session (`unseen_sessions`), made by the fixed schemes' makers
(schemes.py) on one record per episode, the objects a lab gives (`given_objects`, given.py's
rule), and splits a caller gives (`check_episode_split`); all written as split files of kind
"episode" whose ids are episode ids. Windows never cross episodes, so a split of episodes is a
split of windows.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

from ...errors import VtsError
from ..format.records import SampleMeta, SplitFile
from .given import objects_split
from .leaks import check_split
from .schemes import (
    TEST_FRACTION,
    SplitReport,
    static_sessions_split,
    unseen_objects_split,
)

if TYPE_CHECKING:
    import pyarrow as pa

#: The `kind` of a split file whose ids are episode ids (index/episodes.parquet).
EPISODE = "episode"
#: The schemes made over episodes, in the order the writer makes them.
EPISODE_SCHEMES = ("unseen_objects", "unseen_sessions")


def split_table(episodes: pa.Table) -> pa.Table:
    """The columns the leak check reads (sample_id, object, session) of index/episodes.parquet:
    an episode's id is its sample id."""
    import pyarrow as pa

    return pa.table({"sample_id": episodes.column("episode_id"),
                     "object": episodes.column("object"),
                     "session": episodes.column("session")})


def _metas(episodes: pa.Table, kind: str) -> list[SampleMeta]:
    """One record per episode, of the kind a scheme's maker takes (no state: an episode has
    many; its source is its own id: every episode a take of its own)."""
    ids, objs, sess = (episodes.column(c).to_pylist() for c in ("episode_id", "object", "session"))
    return [SampleMeta(i, kind, r, o, 0, s, "", None, None, i) for r, (i, o, s)
            in enumerate(zip(ids, objs, sess, strict=True))]


def given_objects_episodes(episodes: pa.Table, held_out: Sequence[str], *, seed: int = 0,
                           val_fraction: float = 0.1, source: str = "") -> SplitFile:
    """given_objects over whole episodes: test every episode of the listed objects, val the
    episodes of whole objects drawn seeded from the rest (given.py's rule, the samples' draw
    when the objects are the same), train the others. A listed object of no episode, or a
    list holding out every object, is one line."""
    ids, objs = (episodes.column(c).to_pylist() for c in ("episode_id", "object"))
    sp = objects_split(sorted(zip(ids, objs, strict=True)), held_out, kind=EPISODE,
                       what="episode", seed=seed, val_fraction=val_fraction, source=source)
    p = sp.params
    return replace(sp, description=(
        f"the episodes of the {len(p['held_out_objects'])} given objects as test; those of "
        f"{len(p['val_objects'])} other whole objects as val (seeded); train the remaining "
        f"{len(p['train_objects'])} objects' episodes"))


def make_episode_splits(episodes: pa.Table, *, seed: int = 0, unseen_k: int | None = None,
                        val_fraction: float = 0.1, test_fraction: float = TEST_FRACTION,
                        holdout_objects: Sequence[str] | None = None,
                        source: str = "") -> SplitReport:
    """Every episode scheme the episodes allow, leak-checked; the others skipped with the
    reason; with holdout_objects also given_objects (a list that does not fit the episodes is
    an error, never skipped: it was asked for). Same episodes and seed: the same split files,
    byte for byte."""
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise VtsError(f"seed must be a non-negative integer, got {seed!r:.80}")
    report = SplitReport()
    try:
        sp = unseen_objects_split(_metas(episodes, "slip"), seed=seed, k=unseen_k,
                                  val_fraction=val_fraction)
        k, n = sp.params["k"], len(sp.params["held_out_objects"]) + len(sp.params["seen_objects"])
        params = {p: sp.params[p] for p in ("k", "held_out_objects", "seen_objects",
                                            "val_fraction")}
        report.splits.append(replace(
            sp, kind=EPISODE, params=params,
            description=f"{k} of {n} objects held out: all their episodes as test; train and "
                        "val from the other objects' episodes"))
    except VtsError as e:
        report.skipped["unseen_objects"] = str(e).replace("samples", "episodes")
    try:
        sp = static_sessions_split(_metas(episodes, "static"), seed=seed,
                                   val_fraction=val_fraction, test_fraction=test_fraction)
        report.splits.append(replace(
            sp, name="unseen_sessions", kind=EPISODE,
            description="whole sessions held out as test, chosen to keep every object in "
                        "every part"))
    except VtsError as e:
        report.skipped["unseen_sessions"] = (str(e).replace("static_sessions", "unseen_sessions")
                                             .replace("sample", "episode"))
    if holdout_objects is not None:
        report.splits.append(given_objects_episodes(episodes, holdout_objects, seed=seed,
                                                    val_fraction=val_fraction, source=source))
    table = split_table(episodes)
    for sp in report.splits:
        leaks = episode_leaks(sp, table)
        if leaks:  # the makers keep parts apart: a leak here is a bug, never a dataset
            raise AssertionError(f"{sp.name}: {leaks[0]}")
    return report


def episode_leaks(split: SplitFile, table: pa.Table) -> list[str]:
    """Every id of no episode, id in two parts, and object or session shared by parts the
    split's rules keep apart (`check_split` on split_table's columns), one line each."""
    found = check_split(split, {EPISODE: table})
    unknown = [f"episode {i!r} in {p} is not in the dataset"
               for p, ids in found.unknown.items() for i in ids.to_pylist()]
    leaks = [re.sub(r"^(\d+ )?sample(s?) ", r"\1episode\2 ", x) for x in found.leaks]
    return unknown + leaks + found.problems


def split_sizes(splits: Sequence[SplitFile]) -> Mapping[str, dict[str, int]]:
    """Episodes per part of every split (info.json counts.splits)."""
    return {sp.name: {p: len(ids) for p, ids in sp.parts.items()} for sp in splits}


def check_episode_split(split: SplitFile, episodes: pa.Table, source: str = "") -> None:
    """Refuse a split of episodes a caller gives (`add_split`, `--split-file`) whose parts
    name an id of no episode, hold an episode twice or in two parts, or break its disjoint
    rules: one line, the first problem and how many more."""
    if split.kind != EPISODE:
        raise VtsError(f"split {split.name!r} is of kind {split.kind!r}, not {EPISODE!r}",
                       source or None)
    leaks = episode_leaks(split, split_table(episodes))
    if leaks:
        more = f" (and {len(leaks) - 1} more)" if len(leaks) > 1 else ""
        raise VtsError(f"split {split.name} leaks: {leaks[0]}{more}", source or None)


def same_held_out(samples: SplitFile, episodes: SplitFile) -> list[str]:
    """The samples' given_objects and the episodes' one (a dataset with both) hold out the
    same objects: one line when they do not (a model tested on one would have trained on the
    other's test objects)."""
    a = sorted(samples.params.get("held_out_objects") or [])
    b = sorted(episodes.params.get("held_out_objects") or [])
    if a == b:
        return []
    return [f"the samples' {samples.name} holds out {', '.join(a) or 'no object'}, the "
            f"episodes' {episodes.name} {', '.join(b) or 'no object'}: a dataset's two "
            "given_objects splits hold out the same objects"]
