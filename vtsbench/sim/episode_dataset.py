"""`vtsbench simulate-episodes`: continuous simulated takes written as a dataset of episodes
(`vtsbench.create`) with their per-frame labels and slip onsets, and the paper's 8-frame slip
samples and static frames declared as views of them (format 1.3), so that the standard recipes
train on its slip splits and streams are scored on its episode splits.

Takes are rendered in worker processes (each from the seed and its number alone) and written
in take order, so the same options give the same dataset with any number of workers. A killed
run resumes with the writer's resume: saved takes are kept and the next one is rendered again.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import VtsError
from ..labels import label_contact_window
from .episodes import LABEL_WINDOW, EpisodePlan, SimEpisode, plan_episodes, render_episode

SENSOR_ID = "vtsbench-sim"
#: Frames between the starts of two slip samples of a take (`--sample-stride`; the splits
#: over samples keep a take's windows, overlapping or not, in one part), and the most it may
#: be; frames between two static frames. 4, not the samples' length 8: twice the windows,
#: near-onset ones included. The flow tree trained at stride 4 caught slip on streams of
#: unseen objects' takes sooner and with fewer false alarms than at 8, and stride 2 (twice
#: the samples again) as at 4 (docs/benchmarks.md, "Stream evaluation").
SAMPLE_STRIDE = 4
MAX_SAMPLE_STRIDE = 64
STATIC_STRIDE = 8
#: The per-frame values stored with each take (beside state and direction).
FRAME_COLUMNS = ("phase", "x_mm", "y_mm", "indent_mm", "in_contact")


@dataclass(frozen=True)
class EpisodeOptions:
    """What the takes are; recorded with every take (its `simulation` column) so that a
    resume with other options is refused."""

    n_episodes: int
    n_objects: int
    n_sessions: int = 3
    fps: float = 25.0
    seconds: float = 6.0
    size: tuple[int, int] = (240, 320)
    seed: int = 0
    mm_per_px: float | None = None
    truth: bool = False
    no_slip_share: float = 0.25
    gel: str | None = None
    sample_stride: int = SAMPLE_STRIDE

    def key(self) -> str:
        """The options as one short JSON text (the number of takes left out: a resume may
        ask for more)."""
        d = dataclasses.asdict(self)
        d.pop("n_episodes")
        d["size"] = list(self.size)
        return json.dumps(d, sort_keys=True, separators=(",", ":"))


@dataclass(frozen=True)
class _Job:
    plan: EpisodePlan
    options: EpisodeOptions
    capture: Any
    appearance: Any


def _render(job: _Job) -> SimEpisode:
    """One take (in a worker)."""
    o = job.options
    return render_episode(job.plan, seed=o.seed, size=o.size, fps=o.fps, seconds=o.seconds,
                          mm_per_px=o.mm_per_px, capture=job.capture,
                          appearance=job.appearance, truth=o.truth)


def episode_samples(ep: SimEpisode, frames_per_sequence: int = LABEL_WINDOW,
                    stride: int = SAMPLE_STRIDE, static_stride: int = STATIC_STRIDE
                    ) -> list[tuple[str, int, dict[str, Any]]]:
    """(kind, first frame, labels) of a take's samples: slip sequences of frames_per_sequence
    frames every `stride` frames, labelled by the rule on the frames they hold (windows with no
    contact or no state left out), and static frames in contact from the hold phases every
    `static_stride` frames."""
    out: list[tuple[str, int, dict[str, Any]]] = []
    n, t_n = len(ep.frames), frames_per_sequence
    mpp = (ep.mm_per_px, ep.mm_per_px)

    def at(t: int) -> tuple[float, float] | None:
        c = ep.contact_px[t]
        return None if np.isnan(c).any() else (round(float(c[0]), 3), round(float(c[1]), 3))

    for a in range(0, n - t_n + 1, stride):
        b = a + t_n
        if not ep.in_contact[a:b].any():
            continue
        lab = label_contact_window([tuple(p) for p in ep.position_mm[a:b].tolist()],
                                   ep.depth_mm[a:b].tolist(), ep.in_contact[a:b].tolist())
        if lab.state is None:
            continue
        out.append(("slip", a, {
            "state": lab.state, "direction": lab.direction,
            "motion_mm": (round(lab.motion_mm[0], 6), round(lab.motion_mm[1], 6)),
            "press_depth_mm": round(max(0.0, float(ep.depth_mm[b - 1])), 6),
            "contact_px": at(b - 1), "mm_per_px": mpp}))
    for t in range(0, n, static_stride):
        if ep.phase[t] in ("hold", "contact") and ep.in_contact[t]:
            out.append(("static", t, {"press_depth_mm": round(float(ep.depth_mm[t]), 6),
                                      "contact_px": at(t), "mm_per_px": mpp}))
    return out


def _save(w: Any, ep: SimEpisode, options: EpisodeOptions, session: str) -> int:
    """Write one take: frames, per-frame labels and values, the onset and its options."""
    extra = {"phase": ep.phase,
             "x_mm": [round(float(v), 6) for v in ep.position_mm[:, 0]],
             "y_mm": [round(float(v), 6) for v in ep.position_mm[:, 1]],
             "indent_mm": [round(float(v), 6) for v in ep.depth_mm],
             "in_contact": [bool(v) for v in ep.in_contact]}
    return w.add_episode(ep.frames, ep.timestamps.tolist(), ep.states, ep.directions,
                         depth=None if ep.depth is None else np.maximum(ep.depth, 0.0),
                         contact=ep.contact, extra=extra, object=ep.plan.object,
                         session=session, slip_onset_s=ep.slip_onset_s,
                         episode_id=f"episode-{ep.plan.number:06d}",
                         simulation=options.key(),
                         slip="yes" if ep.plan.slip else "no",
                         slip_direction=None if ep.direction is None else str(ep.direction),
                         slip_mm=str(ep.meta["slip_mm"]),
                         phases=json.dumps(ep.meta["phases"]))


def _add_samples(w: Any, ep: SimEpisode, stride: int = SAMPLE_STRIDE) -> int:
    """Declare the take's samples (slip windows every `stride` frames) not yet declared (a
    resumed writer keeps the committed ones); returns how many were added."""
    eid = f"episode-{ep.plan.number:06d}"
    added = 0
    for kind, start, labels in episode_samples(ep, w.frames_per_sequence, stride):
        sid = f"{eid}-{'s' if kind == 'slip' else 'f'}{start:06d}"
        if sid not in w.sample_ids:
            w.add_sample(kind, episode=eid, start=start, sample_id=sid, **labels)
            added += 1
    return added


def _check(options: EpisodeOptions, workers: int) -> None:
    """One line for options that cannot be simulated, before any work."""
    from .. import limits as lim
    from ..limits import check_range
    from .appearance import GELS
    from .episodes import _min_frames, default_mm_per_px
    from .plan import size_problem

    check_range("--episodes", options.n_episodes, 1, lim.MAX_SIM_ENTRIES)
    check_range("--sessions", options.n_sessions, 1, lim.MAX_SIM_SESSIONS)
    check_range("--workers", workers, 1, lim.MAX_WORKERS)
    check_range("--seed", options.seed, 0, lim.MAX_SEED)
    check_range("--sample-stride", options.sample_stride, 1, MAX_SAMPLE_STRIDE)
    check_range("--fps", options.fps, 1.0, 1000.0)
    check_range("--seconds", options.seconds, 0.1, 3600.0)
    mpp = default_mm_per_px(options.size) if options.mm_per_px is None else options.mm_per_px
    problem = size_problem(options.size, mpp, False)
    if problem:
        raise VtsError(problem)
    n = round(options.fps * options.seconds)
    if n < _min_frames():
        raise VtsError(f"a take of {options.seconds:g} s at {options.fps:g} fps is {n} frames; "
                       f"at least {_min_frames()} (more --seconds or a higher --fps)")
    if n > lim.MAX_FRAMES:
        raise VtsError(f"a take of {n} frames is more than {lim.MAX_FRAMES} (fewer --seconds or "
                       "a lower --fps)")
    if options.gel is not None and options.gel not in GELS:
        raise VtsError(f"--gel must be one of {', '.join(GELS)}, got {options.gel!r}")


def _rendered(jobs: list[_Job], workers: int) -> Iterator[SimEpisode]:
    """The takes in job order, rendered in a process pool (at most 2 x workers in flight)."""
    from .simulate import _set_threads

    if workers == 1 or len(jobs) <= 1:
        for job in jobs:
            yield _render(job)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    ctx = multiprocessing.get_context("spawn")  # no fork of the parent's threads' locks
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                             initializer=_set_threads) as pool:
        futures: dict[int, Any] = {}
        nxt = 0
        try:
            for i in range(len(jobs)):
                while nxt < len(jobs) and nxt < i + 2 * workers:
                    futures[nxt] = pool.submit(_render, jobs[nxt])
                    nxt += 1
                yield futures.pop(i).result()
        finally:
            for f in futures.values():
                f.cancel()


def simulate_episodes(out: str | Path, options: EpisodeOptions, *, workers: int = 1,
                      resume: bool = True, overwrite: bool = False, progress: bool = False,
                      shard_mb: float = 32.0) -> Path:
    """Render options.n_episodes takes and write them, their labels and their samples as a
    dataset at `out` (resume: go on from a killed run's saved takes); returns `out`."""
    import vtsbench

    from .appearance import DEFAULT_GEL, sensor_appearance
    from .simulate import session_capture

    _check(options, workers)
    plans = plan_episodes(options.seed, options.n_episodes, options.n_objects,
                          options.n_sessions, options.no_slip_share)
    app = sensor_appearance(options.gel or DEFAULT_GEL)
    captures = [dataclasses.replace(session_capture(options.seed, s)[0], gel=options.seed)
                for s in range(options.n_sessions)]
    arrays = ("rgb", "depth", "contact") if options.truth else ("rgb",)
    with vtsbench.create(out, fps=options.fps, arrays=arrays, sensor=SENSOR_ID,
                         name=Path(out).name, resume=resume, overwrite=overwrite,
                         shard_mb=shard_mb, seed=options.seed,
                         frames_per_sequence=LABEL_WINDOW) as w:
        saved = w.saved_episodes
        for rec in saved:
            if rec.get("simulation") != options.key():
                raise VtsError("the partial dataset was simulated with other options "
                               f"({rec.get('simulation')!r:.200}); run again with "
                               "them, or without --resume", w.partial)
        if len(saved) > len(plans):
            raise VtsError(f"the partial dataset holds {len(saved)} takes, more than the "
                           f"{len(plans)} asked", w.partial)
        # a saved take whose samples were not committed yet (killed before the next save)
        redo = [p for p in plans[:len(saved)]
                if not any(s.startswith(f"episode-{p.number:06d}-") for s in w.sample_ids)]
        todo = plans[len(saved):]
        jobs = [_Job(p, options, captures[p.session], app) for p in redo + todo]
        bar_cm = _bar(progress, len(jobs))
        with bar_cm as bar:
            task = bar.add_task("simulating takes", total=len(jobs)) if bar else None
            for ep in _rendered(jobs, workers):
                if ep.plan.number >= len(saved):
                    _save(w, ep, options, f"s{ep.plan.session:02d}")
                _add_samples(w, ep, options.sample_stride)
                if bar is not None:
                    bar.advance(task)
    return Path(out)


def _bar(progress: bool, total: int) -> Any:
    """The progress bar of the takes (or nothing)."""
    from contextlib import nullcontext

    if not progress:
        return nullcontext(None)
    from rich.progress import BarColumn, MofNCompleteColumn, TimeRemainingColumn

    from ..progress import progress_bar

    return progress_bar("[progress.description]{task.description}", BarColumn(),
                        MofNCompleteColumn(), TimeRemainingColumn(), transient=False)
