"""The fixed split schemes of docs/dataset.md, registered by name in SCHEMES and made once at
build time (the build leak-checks them: splits/leaks.py).

Every scheme sorts the samples by id and draws from a numpy Generator seeded from (seed, scheme
name), so the same samples and seed give byte-identical split files whatever the input order.
"""

from __future__ import annotations

import hashlib
import itertools
import math
import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ...errors import VtsError
from ...labels import STATES
from ..format.records import PART_ORDER, SampleMeta, SplitFile
from .leaks import BAND, OUTSIDE, UNKNOWN, location_keys

#: Held-out contact bands of static_locations: fractions of the frame width along x.
DEFAULT_BANDS: tuple[tuple[float, float], ...] = ((1 / 3, 2 / 3),)
TEST_FRACTION = 0.2
#: Session-to-part assignments tried: all of them up to this many, else this many at random.
MAX_ASSIGNMENTS = 20000
#: Random draws of the held-out objects of unseen_objects, to find one that has every state.
HELD_OUT_DRAWS = 64


@dataclass
class SplitReport:
    """The split files made, and the schemes skipped with the reason."""

    splits: list[SplitFile] = field(default_factory=list)
    skipped: dict[str, str] = field(default_factory=dict)

    def get(self, name: str) -> SplitFile | None:
        return next((s for s in self.splits if s.name == name), None)


def rng_for(name: str, seed: int) -> np.random.Generator:
    """The Generator of one scheme: seeded from seed and the sha256 of the name (never hash())."""
    salt = int.from_bytes(hashlib.sha256(name.encode()).digest()[:8], "little")
    return np.random.default_rng([seed, salt])


def default_unseen_k(n_objects: int) -> int:
    """K objects held out by default: a third, rounded half up, at least one (5 of 15)."""
    return max(1, math.floor(n_objects / 3 + 0.5))


def make_splits(samples: Iterable[SampleMeta], *, seed: int = 0, unseen_k: int | None = None,
                val_fraction: float = 0.1, folds: int = 5, test_fraction: float = TEST_FRACTION,
                location_bands: Sequence[tuple[float, float]] = DEFAULT_BANDS,
                resolution: tuple[int, int] | None = None) -> SplitReport:
    """Every scheme that the samples allow; the others are skipped with the reason.

    Bad parameters (and an explicit unseen_k >= the number of objects) raise VtsError.
    """
    _check_params(seed, unseen_k, val_fraction, folds, test_fraction, location_bands)
    ss = _sorted(samples)
    n_obj = len({s.object for s in ss if s.kind == "slip"})
    if unseen_k is not None and n_obj and unseen_k >= n_obj:
        raise VtsError(f"unseen_objects: cannot hold out {unseen_k} of {n_obj} objects; "
                       "at least one must stay seen")
    params = SchemeParams(seed, unseen_k, val_fraction, folds, test_fraction,
                          tuple(location_bands), resolution)
    report = SplitReport()
    for name, make in REGISTRY.items():
        try:
            report.splits.append(make(ss, params, report))
        except VtsError as e:
            report.skipped[name] = str(e)
    return report


@dataclass(frozen=True)
class SchemeParams:
    """The parameters every scheme maker is given (each reads the ones it needs)."""

    seed: int
    unseen_k: int | None
    val_fraction: float
    folds: int
    test_fraction: float
    bands: tuple[tuple[float, float], ...]
    resolution: tuple[int, int] | None


def _make_unseen(ss: list[SampleMeta], p: SchemeParams, made: SplitReport) -> SplitFile:
    return unseen_objects_split(ss, seed=p.seed, k=p.unseen_k, val_fraction=p.val_fraction)


def _make_seen(ss: list[SampleMeta], p: SchemeParams, made: SplitReport) -> SplitFile:
    unseen = made.get("unseen_objects")  # seen holds out no object that unseen_objects tests
    held = [] if unseen is None else list(unseen.params["held_out_objects"])
    return seen_split(ss, seed=p.seed, held_out=held, val_fraction=p.val_fraction,
                      test_fraction=p.test_fraction)


def _make_folds(ss: list[SampleMeta], p: SchemeParams, made: SplitReport) -> SplitFile:
    return object_folds_split(ss, seed=p.seed, folds=p.folds)


def _make_sessions(ss: list[SampleMeta], p: SchemeParams, made: SplitReport) -> SplitFile:
    return static_sessions_split(ss, seed=p.seed, val_fraction=p.val_fraction,
                                 test_fraction=p.test_fraction)


def _make_locations(ss: list[SampleMeta], p: SchemeParams, made: SplitReport) -> SplitFile:
    return static_locations_split(ss, seed=p.seed, val_fraction=p.val_fraction,
                                  resolution=p.resolution, bands=p.bands)


#: The fixed schemes by name, in the order a build makes them (a maker may read the splits
#: made before it: seen reads unseen_objects' held-out objects). A scheme the samples cannot
#: support raises VtsError and is skipped with its reason.
REGISTRY: dict[str, Callable[[list[SampleMeta], SchemeParams, SplitReport], SplitFile]] = {
    "unseen_objects": _make_unseen,
    "seen": _make_seen,
    "object_folds": _make_folds,
    "static_sessions": _make_sessions,
    "static_locations": _make_locations,
}
SCHEMES = tuple(REGISTRY)


def _check_params(seed: int, unseen_k: int | None, val_fraction: float, folds: int,
                  test_fraction: float, bands: Sequence[tuple[float, float]]) -> None:
    if not isinstance(seed, int) or seed < 0:
        raise VtsError(f"seed must be a non-negative integer, got {seed!r}")
    if unseen_k is not None and unseen_k < 1:
        raise VtsError(f"unseen_objects: K must be at least 1, got {unseen_k}")
    if not 0 <= val_fraction < 1:
        raise VtsError(f"val fraction must be in [0, 1), got {val_fraction}")
    if not 0 < test_fraction < 1 or val_fraction + test_fraction >= 1:
        raise VtsError(f"test fraction must be in (0, 1) and leave room for train, "
                       f"got {test_fraction}")
    if folds < 2:
        raise VtsError(f"object_folds: needs at least 2 folds, got {folds}")
    if not bands or any(not 0 <= lo < hi <= 1 for lo, hi in bands):
        raise VtsError(f"location bands must be (lo, hi) fractions with 0 <= lo < hi <= 1, "
                       f"got {list(bands)}")


def _sorted(samples: Iterable[SampleMeta]) -> list[SampleMeta]:
    """Samples sorted by id; a repeated id is an error."""
    ss = sorted(samples, key=lambda s: s.sample_id)
    for a, b in itertools.pairwise(ss):
        if a.sample_id == b.sample_id:
            raise VtsError(f"sample id {a.sample_id!r} appears twice")
    return ss


def _of_kind(samples: Iterable[SampleMeta], kind: str) -> list[SampleMeta]:
    return [s for s in _sorted(samples) if s.kind == kind]


def _take(ids: list[str], fraction: float, rng: np.random.Generator) -> list[str]:
    """A seeded slice of round(fraction * len) of the (sorted) ids."""
    n = math.floor(fraction * len(ids) + 0.5)
    pick = rng.permutation(len(ids))[:n]
    return sorted(ids[i] for i in pick)


#: A sample's source, `path[start:stop]`: its take is the path.
_SOURCE = re.compile(r"(.*)\[\d+:\d+\]")


def take_of(source: str) -> str:
    """The take (source file or folder) of a sample's `source` field."""
    m = _SOURCE.fullmatch(source)
    return m.group(1) if m else source


def _take_takes(samples: list[SampleMeta], fraction: float, rng: np.random.Generator
                ) -> list[str]:
    """A seeded slice of whole takes holding about `fraction` of the samples: windows cut from
    one take (overlapping or not) never straddle two parts. When every take holds one sample,
    exactly `_take` over the sample ids (the splits of such datasets keep their bytes)."""
    ids = [s.sample_id for s in samples]
    groups: dict[str, list[str]] = {}
    for s in samples:  # a sample of no source is a take of its own
        groups.setdefault(take_of(s.source) if s.source else f"\0{s.sample_id}",
                          []).append(s.sample_id)
    if all(len(g) == 1 for g in groups.values()):
        return _take(ids, fraction, rng)
    takes = sorted(groups)
    want = math.floor(fraction * len(ids) + 0.5)
    picked: list[str] = []
    for i in rng.permutation(len(takes))[:len(takes) - 1]:  # one take at least left to train
        if len(picked) >= want:
            break
        picked += groups[takes[i]]
    return sorted(picked)


def _parts(**parts: list[str]) -> dict[str, list[str]]:
    """Parts in order, an empty val left out."""
    return {p: sorted(v) for p, v in parts.items() if v or p != "val"}


def unseen_objects_split(samples: Iterable[SampleMeta], *, seed: int = 0, k: int | None = None,
                         val_fraction: float = 0.1) -> SplitFile:
    """K whole objects as test, balanced across states; val a slice of the seen objects."""
    name = "unseen_objects"
    slip = _of_kind(samples, "slip")
    if not slip:
        raise VtsError(f"{name}: no slip samples")
    objects = sorted({s.object for s in slip})
    n = len(objects)
    if n < 2:
        raise VtsError(f"{name}: needs at least 2 objects to hold some out, found only "
                       f"{objects[0]!r}")
    k = default_unseen_k(n) if k is None else k
    if not 1 <= k < n:
        raise VtsError(f"{name}: cannot hold out {k} of {n} objects; at least one must stay seen")
    rng = rng_for(name, seed)
    states_of: dict[str, set[str]] = {}
    for s in slip:
        if s.state is not None:
            states_of.setdefault(s.object, set()).add(s.state)
    all_states = set().union(*states_of.values()) if states_of else set()
    held: list[str] = []
    for _ in range(HELD_OUT_DRAWS):  # the first draw that covers every state, else the first
        draw = sorted(objects[i] for i in rng.choice(n, size=k, replace=False))
        covered = set().union(*(states_of.get(o, set()) for o in draw))
        held = held or draw
        if covered == all_states:
            held = draw
            break
    by_state: dict[str, list[str]] = {}
    unknown = 0
    for s in slip:
        if s.object in held:
            if s.state is None:
                unknown += 1
            else:
                by_state.setdefault(s.state, []).append(s.sample_id)
    present = [st for st in STATES if st in by_state]
    unlabelled = not all_states  # no slip sample has a state: nothing to balance
    if not present and not unlabelled:
        raise VtsError(f"{name}: no sample of the held-out objects {held} has a known state")
    if unlabelled:
        m, test = None, [s.sample_id for s in slip if s.object in held]
    else:
        m = min(len(by_state[st]) for st in present)
        test = []
        for st in present:
            ids = by_state[st]
            test += [ids[i] for i in sorted(rng.choice(len(ids), size=m, replace=False))]
    seen = [s for s in slip if s.object not in held]
    seen_ids = [s.sample_id for s in seen]
    val = _take_takes(seen, val_fraction, rng)
    train = sorted(set(seen_ids) - set(val))
    params = {"k": k, "held_out_objects": held,
              "seen_objects": [o for o in objects if o not in held],
              "val_fraction": val_fraction, "test_per_state": m, "test_states": present,
              "missing_states": [st for st in STATES if st in all_states and st not in present],
              "dropped_for_balance": {st: len(by_state[st]) - (m or 0) for st in present},
              "dropped_unknown_state": 0 if unlabelled else unknown}
    if unlabelled:
        params["states_unknown"] = True
    desc = (f"{k} of {n} objects held out as test, "
            + (f"{m} samples per state ({', '.join(present)})" if not unlabelled else
               "all their samples (no sample has a state: not balanced)")
            + "; train and val from the other objects")
    return SplitFile(name, "slip", desc, seed, _parts(train=train, val=val, test=test),
                     ["object:test"], params)


def seen_split(samples: Iterable[SampleMeta], *, seed: int = 0, held_out: Sequence[str] = (),
               val_fraction: float = 0.1, test_fraction: float = TEST_FRACTION) -> SplitFile:
    """The seen objects' slip samples, parts made of whole sessions, stratified by object×state."""
    name = "seen"
    slip = [s for s in _of_kind(samples, "slip") if s.object not in set(held_out)]
    if not slip:
        raise VtsError(f"{name}: no slip samples of seen objects")
    parts, params = _session_parts(name, slip, seed, val_fraction, test_fraction,
                                   lambda s: None if s.state is None else f"{s.object}/{s.state}")
    params = {"seen_objects": sorted({s.object for s in slip}),
              "held_out_objects": sorted(held_out), **params}
    desc = ("seen objects, parts made of whole sessions chosen to keep every object and state "
            "in every part")
    return SplitFile(name, "slip", desc, seed, parts, ["session"], params)


def static_sessions_split(samples: Iterable[SampleMeta], *, seed: int = 0,
                          val_fraction: float = 0.1,
                          test_fraction: float = TEST_FRACTION) -> SplitFile:
    """Static samples, whole sessions held out as test (and val when a third session exists)."""
    name = "static_sessions"
    static = _of_kind(samples, "static")
    if not static:
        raise VtsError(f"{name}: no static samples")
    parts, params = _session_parts(name, static, seed, val_fraction, test_fraction,
                                   lambda s: s.object)
    desc = "whole sessions held out as test, chosen to keep every object in every part"
    return SplitFile(name, "static", desc, seed, parts, ["session"], params)


def _session_parts(name: str, samples: list[SampleMeta], seed: int, val_fraction: float,
                   test_fraction: float, group_of: Callable[[SampleMeta], str | None]
                   ) -> tuple[dict[str, list[str]], dict[str, object]]:
    """Parts made of whole sessions: the seeded assignment that keeps the most groups in every
    part, then the one whose part sizes are nearest the target fractions."""
    sessions = sorted({s.session for s in samples})
    if len(sessions) < 2:
        raise VtsError(f"{name}: every sample comes from one session ({sessions[0]!r}), so no "
                       "part can hold out a session; record another session")
    params: dict[str, object] = {"val_fraction": val_fraction, "test_fraction": test_fraction}
    names = list(PART_ORDER)
    if val_fraction == 0:
        names.remove("val")
        params["val"] = "none: val fraction is 0"
    elif len(sessions) < 3:
        names.remove("val")
        params["val"] = f"dropped: {len(sessions)} sessions cannot make 3 session-disjoint parts"
    target = {"train": 1 - val_fraction - test_fraction, "val": val_fraction,
              "test": test_fraction}
    want = np.array([target[p] for p in names])
    want /= want.sum()
    groups = sorted({g for s in samples if (g := group_of(s)) is not None})
    s_idx = {x: i for i, x in enumerate(sessions)}
    g_idx = {x: i for i, x in enumerate(groups)}
    counts = np.zeros((len(sessions), len(groups)), np.float32)
    sizes = np.zeros(len(sessions))
    for s in samples:
        sizes[s_idx[s.session]] += 1
        g = group_of(s)
        if g is not None:
            counts[s_idx[s.session], g_idx[g]] += 1
    rng = rng_for(name, seed)
    n_s, n_p = len(sessions), len(names)
    if n_p ** n_s <= MAX_ASSIGNMENTS:
        cand = np.array(list(itertools.product(range(n_p), repeat=n_s)), dtype=np.int64)
    else:
        cand = rng.integers(0, n_p, size=(MAX_ASSIGNMENTS, n_s))
    onehot = np.eye(n_p, dtype=np.float32)[cand]  # (C, S, P)
    every_part = onehot.max(axis=1).min(axis=1) > 0  # every part gets a session
    cand, onehot = cand[every_part], onehot[every_part]
    if not len(cand):
        raise VtsError(f"{name}: found no assignment of {n_s} sessions to {n_p} parts")
    shuffle = rng.permutation(len(cand))
    cand, onehot = cand[shuffle], onehot[shuffle]
    cover = np.concatenate([(np.einsum("csp,sg->cpg", onehot[i:i + 2048], counts) > 0).sum(
        axis=(1, 2)) for i in range(0, len(cand), 2048)])  # chunks bound the memory
    frac = np.einsum("csp,s->cp", onehot, sizes) / sizes.sum()
    err = np.round(np.abs(frac - want).sum(axis=1), 9)
    best = cand[np.lexsort((err, -cover))[0]]
    part_of = {x: names[best[i]] for i, x in enumerate(sessions)}
    parts = {p: [s.sample_id for s in samples if part_of[s.session] == p] for p in names}
    present = {p: {group_of(s) for s in samples if part_of[s.session] == p} for p in names}
    missing = [f"{g} not in {p}" for g in groups for p in names if g not in present[p]]
    params.update({"sessions": {p: [x for x in sessions if part_of[x] == p] for p in names},
                   "groups": len(groups),
                   "groups_in_every_part": sum(all(g in present[p] for p in names)
                                               for g in groups),
                   "missing": missing})
    return parts, params


def object_folds_split(samples: Iterable[SampleMeta], *, seed: int = 0,
                       folds: int = 5) -> SplitFile:
    """k = min(folds, objects) folds of whole objects, balanced by sample count (seeded greedy)."""
    name = "object_folds"
    slip = _of_kind(samples, "slip")
    if not slip:
        raise VtsError(f"{name}: no slip samples")
    count: dict[str, int] = {}
    for s in slip:
        count[s.object] = count.get(s.object, 0) + 1
    objects = sorted(count)
    if len(objects) < 2:
        raise VtsError(f"{name}: needs at least 2 objects to make folds, found only "
                       f"{objects[0]!r}")
    k = min(folds, len(objects))
    rng = rng_for(name, seed)
    order = [objects[i] for i in rng.permutation(len(objects))]
    order.sort(key=lambda o: -count[o])  # largest first; ties in seeded order
    load: list[int] = [0] * k
    members: list[list[str]] = [[] for _ in range(k)]
    for o in order:
        j = min(range(k), key=lambda f: (load[f], len(members[f]), f))
        load[j] += count[o]
        members[j].append(o)
    fold_of = {o: j for j, objs in enumerate(members) for o in objs}
    parts = {f"fold{j}": [s.sample_id for s in slip if fold_of[s.object] == j] for j in range(k)}
    params = {"k": k, "folds_requested": folds,
              "objects": {f"fold{j}": sorted(members[j]) for j in range(k)},
              "samples": {f"fold{j}": load[j] for j in range(k)}}
    desc = f"{k} folds of whole objects, every object in exactly one fold"
    return SplitFile(name, "slip", desc, seed, parts, ["object"], params)


def static_locations_split(samples: Iterable[SampleMeta], *, seed: int = 0,
                           val_fraction: float = 0.1, resolution: tuple[int, int] | None = None,
                           bands: Sequence[tuple[float, float]] = DEFAULT_BANDS) -> SplitFile:
    """Static samples whose contact x lies in a band of the frame width as test; unknown
    locations go to train."""
    name = "static_locations"
    static = _of_kind(samples, "static")
    if not static:
        raise VtsError(f"{name}: no static samples")
    if resolution is None:
        raise VtsError(f"{name}: the frame width is needed to place the held-out band "
                       "(pass resolution)")
    width = int(resolution[1])
    bands_px = [[lo * width, hi * width] for lo, hi in bands]
    by_key: dict[str, list[str]] = {BAND: [], OUTSIDE: [], UNKNOWN: []}
    xs = np.array([np.nan if s.contact_x_px is None else s.contact_x_px for s in static],
                  np.float64)
    for s, key in zip(static, location_keys(xs, bands_px), strict=True):
        by_key[key].append(s.sample_id)
    if not by_key[BAND]:
        raise VtsError(f"{name}: no static sample has its contact x in the held-out band(s) "
                       f"{[list(b) for b in bands]} of the frame width")
    if not by_key[OUTSIDE]:
        raise VtsError(f"{name}: no static sample has its contact x outside the held-out band")
    val = _take(by_key[OUTSIDE], val_fraction, rng_for(name, seed))
    train = sorted(set(by_key[OUTSIDE]) - set(val)) + by_key[UNKNOWN]
    params = {"location": {"axis": "x", "bands": [list(b) for b in bands], "bands_px": bands_px,
                           "width_px": width},
              "val_fraction": val_fraction, "unknown_location_in_train": len(by_key[UNKNOWN])}
    desc = ("contacts whose x lies in the held-out band(s) of the frame width as test; "
            "samples without a known contact in train")
    return SplitFile(name, "static", desc, seed, _parts(train=train, val=val, test=by_key[BAND]),
                     ["location:test"], params)

