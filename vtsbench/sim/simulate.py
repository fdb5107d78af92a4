"""`vtsbench simulate`: plan the entries, render them in worker processes, write the folder.

Each entry is rendered and written by one task whose randomness comes only from the seed and
the entry's kind and number; the main process writes the backgrounds and the manifest in entry
order, so the same seed gives the same bytes with any number of workers. The folder is built
in a staging directory that takes its final name only when complete.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import VtsError
from ..recordings.manifest import Circle, Entry, Labels, Manifest, Mount, Session, Source
from .objects import BALL_RADIUS_MM, OBJECTS
from .optics import DEFAULT_LIGHTS, LIGHTS, Capture
from .plan import (
    DEFAULT_GENERATOR,
    GENERATORS,
    EntryPlan,
    entry_rng,
    make_plans,
    press_scene,
    sequence_plan_scene,
    session_rng,
    size_problem,
    static_scene,
)
from .scene import Scene

if TYPE_CHECKING:
    from .appearance import Appearance

SENSOR_ID = "vtsbench-sim"
FPS = 30.0
#: Read noise (DN) of a session is drawn uniformly from this range.
READ_NOISE_DN = (1.0, 2.0)


def sensor_id(lights: str = DEFAULT_LIGHTS) -> str:
    """The simulated sensor's id: one per light layout, so that a calibration made under one
    layout is refused for frames of another (`load_calibration(..., sensor=)`)."""
    return SENSOR_ID if lights == DEFAULT_LIGHTS else f"{SENSOR_ID}-{lights}"


@dataclass(frozen=True)
class Job:
    """Everything a worker needs to render and write one entry."""

    plan: EntryPlan
    session_id: str
    capture: Capture
    seed: int
    size: tuple[int, int]
    mm_per_px: float
    frames: int
    root: str
    generator: int = 1
    #: Generator 2: the folder's sensor (its gel and imprint gain), shared by every entry.
    appearance: Appearance | None = None
    #: The sensor's light layout (a name of `optics.LIGHTS`).
    lights: str = DEFAULT_LIGHTS


def session_capture(seed: int, session: int) -> tuple[Capture, np.random.Generator]:
    """A session's camera settings and the generator of its background frame."""
    rng = session_rng(seed, session)
    return Capture(read_noise=round(float(rng.uniform(*READ_NOISE_DN)), 4), gel=session), rng


def _set_threads() -> None:
    """One OpenCV thread per process: deterministic and fair to the other workers."""
    import cv2

    cv2.setNumThreads(1)


def _round(x: float, n: int = 6) -> float:
    """Round for the manifest (short, stable JSON)."""
    return round(float(x), n)


def _centroid(mask: np.ndarray) -> tuple[float, float] | None:
    """Centroid (x, y) in px of a mask, or None when empty."""
    ys, xs = np.nonzero(mask)
    if not xs.size:
        return None
    return _round(xs.mean(), 3), _round(ys.mean(), 3)


def _path_meta(scene: Scene) -> dict:
    """Generator-2 facts of a sequence for the manifest: speed profile, rotation over the
    window (deg, counter-clockwise), contact made or lost."""
    meta: dict = {}
    if scene.path is not None and scene.effects.motion:
        meta["profile"] = scene.path.profile
        meta["turn_deg"] = _round(scene.path.rotations_deg[-1], 4)
        if scene.path.contact_change is not None:
            meta["contact_change"] = scene.path.contact_change
    return meta


def run_job(job: Job) -> Entry:
    """Render one entry, write its frames and truth, and return its manifest entry."""
    from ..labels import label_contact_window
    from ..recordings.media import write_png
    from ..recordings.truth import Truth, write_truth
    from .scene import render

    plan = job.plan
    root = Path(job.root)
    rng = entry_rng(job.seed, plan.kind, plan.number)
    motion = None
    gen = job.generator
    if plan.kind == "static":
        scene = static_scene(plan, rng, job.size, job.mm_per_px, gen, job.appearance)
    elif plan.kind == "sequence":
        scene, motion = sequence_plan_scene(plan, rng, job.size, job.mm_per_px, job.frames, gen,
                                            job.appearance)
    else:
        scene = press_scene(rng, job.size, job.mm_per_px, gen, job.appearance)
    if job.lights != DEFAULT_LIGHTS:
        scene = dataclasses.replace(scene, lights=job.lights)
    rendered = render(scene, job.capture, rng)
    truth = f"truth/{plan.id}.npz"
    write_truth(root / truth, Truth(rendered.depth_mm, rendered.grad, rendered.contact,
                                    rendered.motion_px))
    depth = max(0.0, float(scene.depths_mm[-1]))  # below 0: the object is above the gel
    contact_px = _centroid(rendered.contact[-1])
    obj = scene.obj
    meta = {"group": obj.cls.group, "rotation_deg": _round(obj.rotation_deg, 4),
            "scale": _round(obj.scale, 4),
            "start_px": [_round(scene.centers_px[0][0], 4), _round(scene.centers_px[0][1], 4)]}
    if gen >= 2:  # generator 1 entries carry no mark (their bytes are kept)
        meta["generator"] = gen
    if plan.kind == "sequence":
        assert motion is not None
        folder = f"sequences/{plan.id}"
        (root / folder).mkdir()
        digits = max(3, len(str(job.frames - 1)))
        for t, frame in enumerate(rendered.frames):
            write_png(root / folder / f"{t:0{digits}d}.png", frame)
        meta["intended_state"] = plan.state
        meta["depth0_mm"] = float(motion.depth0_mm)
        if gen >= 2:
            lab = label_contact_window(motion.positions_mm(job.frames), scene.depths_mm,
                                       rendered.contact.any(axis=(1, 2)).tolist())
            meta.update(_path_meta(scene))
        else:
            lab = motion.label()
        labels = Labels(state=lab.state, direction=lab.direction,
                        motion_mm=(float(lab.motion_mm[0]), float(lab.motion_mm[1])),
                        press_depth_mm=depth, contact_px=contact_px)
        return Entry(plan.id, "sequence", job.session_id, Source(folder, start=0, stop=job.frames),
                     object=plan.object, labels=labels, truth=truth, meta=meta)
    sub = "static" if plan.kind == "static" else "presses"
    path = f"{sub}/{plan.id}.png"
    write_png(root / path, rendered.frames[0])
    if plan.kind == "static":
        return Entry(plan.id, "static", job.session_id, Source(path), object=plan.object,
                     labels=Labels(press_depth_mm=depth, contact_px=contact_px), truth=truth,
                     meta=meta)
    cx, cy = scene.centers_px[0]
    area = int(rendered.contact[0].sum())
    circle = Circle(_round(cx, 4), _round(cy, 4), _round(math.sqrt(area / math.pi), 4))
    return Entry(plan.id, "press", job.session_id, Source(path), object=plan.object,
                 labels=Labels(press_depth_mm=depth, contact_px=(circle.x, circle.y)),
                 ball_radius_mm=BALL_RADIUS_MM, circle=circle, truth=truth,
                 meta={"depth_mm": depth, **({"generator": gen} if gen >= 2 else {})})


def _check_args(n_static: int, n_sequences: int, n_presses: int, n_objects: int,
                size: tuple[int, int], frames: int, n_sessions: int, mm_per_px: float,
                workers: int, seed: int) -> None:
    """Raise a one-line VtsError for arguments that cannot be simulated, or that are past the
    bounds of vtsbench/limits.py (checked before any work)."""
    from .. import limits as lim
    from ..limits import check_range

    for name, n in (("static", n_static), ("sequences", n_sequences), ("presses", n_presses)):
        check_range(f"--{name}", n, 0, lim.MAX_SIM_ENTRIES)
    if not 1 <= n_objects <= len(OBJECTS):
        raise VtsError(f"--objects must be between 1 and {len(OBJECTS)}, got {n_objects}")
    check_range("--frames", frames, 2, lim.MAX_FRAMES)
    check_range("--sessions", n_sessions, 1, lim.MAX_SIM_SESSIONS)
    check_range("--workers", workers, 1, lim.MAX_WORKERS)
    check_range("--seed", seed, 0, lim.MAX_SEED)
    check_range("--mm-per-px", mm_per_px, 1e-4, 10.0)
    problem = size_problem(size, mm_per_px, n_presses > 0)
    if problem:
        raise VtsError(problem)
    if n_sequences and frames * size[0] * size[1] > lim.MAX_SEQUENCE_PIXELS:
        raise VtsError(f"a sequence of {frames} frames of {size[0]}x{size[1]} is "
                       f"{frames * size[0] * size[1] / 1e6:.0f} million pixels; at most "
                       f"{lim.MAX_SEQUENCE_PIXELS / 1e6:.0f} million (frames x height x "
                       "width): use fewer --frames or a smaller --size")


def _run_jobs(jobs: list[Job], workers: int, progress: bool) -> list[Entry]:
    """Run the jobs (in a process pool when workers > 1) and return entries in job order."""
    from contextlib import nullcontext

    results: list[Entry | None] = [None] * len(jobs)
    bar_cm = nullcontext(None)
    if progress:
        from rich.progress import BarColumn, MofNCompleteColumn, TimeRemainingColumn

        from ..progress import progress_bar

        bar_cm = progress_bar("[progress.description]{task.description}", BarColumn(),
                              MofNCompleteColumn(), TimeRemainingColumn(), transient=False)
    with bar_cm as bar:
        task = bar.add_task("simulating", total=len(jobs)) if bar is not None else None
        if workers == 1 or len(jobs) <= 1:
            import cv2

            threads = cv2.getNumThreads()
            _set_threads()
            try:
                for i, job in enumerate(jobs):
                    results[i] = run_job(job)
                    if bar is not None:
                        bar.advance(task)
            finally:
                cv2.setNumThreads(threads)
        else:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor, as_completed

            # Spawned, not forked: a fork copies the parent's OpenCV and progress-bar threads'
            # locks in whatever state they are, and the children can deadlock on them.
            ctx = multiprocessing.get_context("spawn")
            with ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                                     initializer=_set_threads) as pool:
                futures = {pool.submit(run_job, job): i for i, job in enumerate(jobs)}
                try:
                    for fut in as_completed(futures):
                        results[futures[fut]] = fut.result()
                        if bar is not None:
                            bar.advance(task)
                except BaseException:
                    for f in futures:
                        f.cancel()
                    raise
    return [r for r in results if r is not None]


def simulate(out: str | Path, *, seed: int = 0, n_static: int = 30, n_sequences: int = 30,
             n_presses: int = 20, n_objects: int = 15, size: tuple[int, int] = (480, 640),
             frames: int = 8, n_sessions: int = 3, mm_per_px: float = 0.03, workers: int = 1,
             overwrite: bool = False, progress: bool = False,
             generator: int = DEFAULT_GENERATOR, gel: str | None = None,
             lights: str = DEFAULT_LIGHTS) -> Manifest:
    """Write a synthetic recordings folder with exact ground truth; returns its manifest.

    generator 1 is the first simulator (rigid shifts at constant speed, clean sensor), kept
    byte for byte; 2 adds contact mechanics, uneven speed, contact made or lost, the gel's
    fixed pattern and a real camera (docs/simulator.md). A generator-2 folder is one sensor:
    every session wears the same gel (`gel`: 'markers' or 'plain', default DEFAULT_GEL) with
    one pattern and imprint gain drawn from the seed, so that the calibration presses and the
    entries share them. lights: the sensor's light layout (`optics.LIGHTS`: 'zones3', three
    coloured zones, the default; 'sides4', red, green, blue and white strips on four sides;
    'uniform', diffuse white light, as on a marker-less uniformly lit sensor).
    """
    from ..atomic import staged_dir
    from ..recordings.manifest import save_manifest
    from ..recordings.media import write_png
    from .optics import capture_frame, sensor

    size = (int(size[0]), int(size[1]))
    mm_per_px = float(mm_per_px)
    _check_args(n_static, n_sequences, n_presses, n_objects, size, frames, n_sessions,
                mm_per_px, workers, seed)
    if generator not in GENERATORS:
        raise VtsError(f"--generator must be one of {', '.join(map(str, GENERATORS))}, "
                       f"got {generator}")
    from .appearance import DEFAULT_GEL, GELS, sensor_appearance

    if gel is not None and gel not in GELS:
        raise VtsError(f"--gel must be one of {', '.join(GELS)}, got {gel!r}")
    if gel is not None and generator < 2:
        raise VtsError("--gel needs --generator 2 (generator 1 has a clean gel)")
    if lights not in LIGHTS:
        raise VtsError(f"--lights must be one of {', '.join(LIGHTS)}, got {lights!r}")
    app = sensor_appearance(gel or DEFAULT_GEL) if generator >= 2 else None
    plans = make_plans(seed, n_static, n_sequences, n_presses, n_objects, n_sessions,
                       per_state=generator >= 2)
    with staged_dir(out, overwrite, marker="recordings.json") as stage:
        sessions, captures = [], []
        fields = sensor(size[0], size[1], mm_per_px, lights=lights)
        for s in range(n_sessions):
            sid = f"s{s:02d}"
            capture, rng = session_capture(seed, s)
            (stage / sid).mkdir()
            if app is not None:  # the sensor's one gel (number: the seed), as entries show it
                from .appearance import background
                from .camera import gel_gain

                capture = dataclasses.replace(capture, gel=seed)
                frame = background(app, fields, capture, rng)
            else:
                frame = capture_frame(fields, capture, rng)
            write_png(stage / sid / "background.png", frame)
            captures.append(capture)
            notes = f"simulated; read noise {capture.read_noise:g} DN"
            if generator >= 2:  # generator 1 folders carry no mark (their bytes are kept)
                notes = (f"simulated, generator {generator}; {gel or DEFAULT_GEL} gel, imprint "
                         f"gain {gel_gain(app, seed):.3f}; read noise {capture.read_noise:g} DN")
            if lights != DEFAULT_LIGHTS:  # the default's notes stay as they were
                notes += f"; lights {lights}"
            sessions.append(Session(sid, sensor_id(lights), size, (mm_per_px, mm_per_px), FPS,
                                    f"{sid}/background.png", mount=Mount(), notes=notes))
        for sub, n in (("static", n_static), ("sequences", n_sequences), ("presses", n_presses),
                       ("truth", len(plans))):
            if n:
                (stage / sub).mkdir()
        jobs = [Job(p, sessions[p.session].id, captures[p.session], seed, size, mm_per_px,
                    frames, str(stage), generator, app, lights) for p in plans]
        entries = _run_jobs(jobs, workers, progress)
        used = ", ".join(c.name for c in OBJECTS[:n_objects])
        manifest = Manifest(
            sessions=sessions, entries=entries, name="vtsbench-sim",
            description=("Synthetic visuo-tactile recordings ("
                         + (f"generator {generator}, " if generator >= 2 else "")
                         + (f"lights {lights}, " if lights != DEFAULT_LIGHTS else "")
                         + f"seed {seed}, {size[0]}x{size[1]} "
                         f"px at {mm_per_px:g} mm/px) with exact ground-truth depth in truth/. "
                         f"Objects: {used}."),
            created_by="vtsbench simulate")
        save_manifest(stage, manifest)
    return manifest
