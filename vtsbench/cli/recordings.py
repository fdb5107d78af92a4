"""The recordings stage's commands: simulate, check, manifest, import-presses, preview, stats
and collect. Each parses its options, calls one library function (imported inside it) and
prints the result."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import typer

from .. import limits as lim
from .options import choice, deprecated, finite, number_option, parse_size, str_option
from .run import console, report_problems, run


def simulate(
    out: Annotated[Path, typer.Argument(help="Recordings folder to create.")],
    seed: Annotated[int, typer.Option(
        min=0, max=lim.MAX_SEED,
        help="Random seed; the same seed writes identical files.")] = 0,
    static: Annotated[int, typer.Option("--static", min=0, max=lim.MAX_SIM_ENTRIES,
                                        help="Static frames.")] = 30,
    sequences: Annotated[int, typer.Option(
        "--sequences", min=0, max=lim.MAX_SIM_ENTRIES,
        help="Sequences (static, press and slip, balanced).")] = 30,
    presses: Annotated[int, typer.Option("--presses", min=0, max=lim.MAX_SIM_ENTRIES,
                                         help="Calibration presses of a 3 mm-radius sphere.")] = 20,
    objects: Annotated[int, typer.Option("--objects", min=1, max=15,
                                         help="Number of object classes to use (of 15).")] = 15,
    size: Annotated[str, typer.Option(
        help=f"Frame size HxW, each side 32 to {lim.MAX_SIDE_PX} pixels.")] = "480x640",
    frames: Annotated[int, typer.Option(
        min=2, max=lim.MAX_FRAMES,
        help=f"Frames per sequence; frames x height x width at most "
             f"{lim.MAX_SEQUENCE_PIXELS // 10**6} million (325 frames of 480x640).")] = 8,
    sessions: Annotated[int, typer.Option(
        min=1, max=lim.MAX_SIM_SESSIONS, help="Sessions (backgrounds, noise draws).")] = 3,
    mm_per_px: Annotated[float, typer.Option(
        callback=finite,
        min=1e-4, max=10.0, help="Scale of the sensor, mm per pixel.")] = 0.03,
    workers: Annotated[int, typer.Option(min=1, max=lim.MAX_WORKERS,
                                         help="Worker processes.")] = 1,
    overwrite: Annotated[bool, typer.Option(
        "--overwrite", help="Replace OUT if it exists.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bar.")] = False,
    generator: Annotated[int, typer.Option(
        min=1, max=2,
        help="Simulator version: 2 (default, benchmark v2's) partial slip, rotation, uneven "
             "speed, contact made or lost, the gel's fixed pattern and a real camera, "
             "calibrated to real video (docs/simulator.md); 1 the first simulator (rigid shifts "
             "at constant speed, clean sensor), the same bytes as before for a seed.")] = 2,
    gel: Annotated[Literal["markers", "plain"] | None, choice(
        help="Generator 2: the sensor's gel, 'markers' (a printed marker grid) or 'plain' "
             "(default); every session of the folder wears it.")] = None,
    lights: Annotated[Literal["zones3", "sides4", "uniform"], choice(
        help="The sensor's light layout: 'zones3' (default), three coloured LED zones round the "
             "gel (GelSight-type); 'sides4', red, green, blue and white strips on four sides, "
             "lower over the gel; 'uniform', diffuse white light from above (a uniformly lit "
             "sensor: a press changes the colour little, and in grey).")] = "zones3",
) -> None:
    """Write a synthetic recordings folder with exact ground-truth depth and gradients.

    Example: [bold]vtsbench simulate data/sim --seed 0 --static 30 --sequences 30 --presses 20[/]
    """
    from ..sim.simulate import simulate as run_sim

    m = run(run_sim, out, seed=seed, n_static=static, n_sequences=sequences, n_presses=presses,
            n_objects=objects, size=parse_size(size), frames=frames, n_sessions=sessions,
            mm_per_px=mm_per_px, workers=workers, overwrite=overwrite, progress=not quiet,
            generator=generator, gel=gel, lights=lights)
    typer.echo(f"wrote {len(m.entries)} entries in {len(m.sessions)} sessions to {out}")


def check(
    folder: Annotated[Path, typer.Argument(help="Recordings folder (with recordings.json).")],
    deep: Annotated[bool, typer.Option(
        "--deep", help="Decode every frame of every video (slow).")] = False,
    workers: Annotated[int, typer.Option(min=1, max=lim.MAX_WORKERS,
                                         help="Threads reading media.")] = 2,
    labels: Annotated[Path | None, typer.Option(
        help="Labels CSV given to `vtsbench manifest --labels`: list its rows that match no "
             "entry.")] = None,
) -> None:
    """Validate a recordings folder and list every problem; exit 1 if there is any.

    Checks the manifest against its schema, then every entry: files present and decodable,
    frame ranges inside the video or folder, resolution as the session says, labels in range
    and consistent (a direction only on a slip), presses with a ball radius.
    """

    from ..recordings.check import check_folder

    report = run(check_folder, folder, deep=deep, workers=workers, labels=labels,
                 progress=True)
    report_problems(report.problems, report.warnings,
                    f"{report.n_entries} entries, {report.n_frames} frames checked: "
                    f"{len(report.problems)} problem(s), {len(report.warnings)} warning(s)")


def manifest(
    folder: Annotated[Path, typer.Argument(help="Folder of existing files to describe.")],
    pattern: Annotated[str, str_option(
        limit=lim.MAX_PATH_TEXT,
        help="File-name pattern relative to FOLDER, e.g. '{object}_{take}.mov'. Fields: object, "
             "take, session, state, direction; '{name:d}' matches digits only; fields match "
             "greedily from the left; '/' matches sub-folders.")],
    kind: Annotated[Literal["static", "sequence", "press"] | None, choice(
        help="static, sequence or press (default: sequence for videos and image folders, "
             "static for images).")] = None,
    sensor: Annotated[str, str_option(help="Sensor id.")] = "unknown",
    session: Annotated[str, str_option(
        help="Session id when the pattern has no {session}.")] = "s0",
    mm_per_px: Annotated[float | None, number_option(
        high=lim.MAX_MM_PER_PX,
        help="mm per pixel, if known.")] = None,
    fps: Annotated[float | None, number_option(
        high=lim.MAX_FPS,
        help="Frame rate (default: read from videos).")] = None,
    background: Annotated[str | None, str_option(
        limit=lim.MAX_PATH_TEXT, help="No-contact frame, relative to FOLDER.")] = None,
    ball_radius_mm: Annotated[float | None, number_option(
        high=lim.MAX_MM,
        help="Ball radius in mm for presses.")] = None,
    circles: Annotated[Path | None, typer.Option(
        help="CSV of press circles: a file column (file|img_names|image|name) and x|center_x, "
             "y|center_y, r|radius in pixels.")] = None,
    window: Annotated[int | None, typer.Option(
        min=1, max=lim.MAX_FRAMES,
        help="Cut videos and folders into sequences of this many frames.")] = None,
    stride: Annotated[int | None, typer.Option(
        min=1, max=lim.MAX_STRIDE,
        help="Step between windows; with --kind static, a static frame every STRIDE "
             "frames of each video or image folder (else its first frame).")] = None,
    overwrite: Annotated[bool, typer.Option(
        "--overwrite", help="Replace an existing recordings.json.")] = False,
    force: Annotated[bool, typer.Option("--force", hidden=True)] = False,
    out: Annotated[Path | None, typer.Option(
        help="Write recordings.json into this folder instead (for read-only data); paths in it "
             "point back to FOLDER.")] = None,
    labels: Annotated[Path | None, typer.Option(
        help="CSV of labels: a file column (file|path|folder, relative to FOLDER; a folder "
             "labels everything in it), optional start,stop frames, and state, direction, "
             "press_depth_mm, object, take or any other column (kept as a field).")] = None,
    marker: Annotated[list[str] | None, str_option(
        limit=lim.MAX_PATH_TEXT,
        help="FILE:FIELD=VALUE: entries with FILE in their folder (or a folder above) get the "
             "label, e.g. slip.txt:state=slip; '!FILE:...' when FILE is absent. Repeatable.")
    ] = None,
) -> None:
    """Write recordings.json for a folder of existing files, matched by a file-name pattern.

    Example: [bold]vtsbench manifest videos --pattern '{object}_{take}.mov' --sensor gsmini[/]
    """
    from ..recordings.importer import ManifestOptions, write_pattern_manifest

    opts = ManifestOptions(pattern=pattern, kind=kind, sensor=sensor, session=session,
                           mm_per_px=mm_per_px, fps=fps, background=background,
                           ball_radius_mm=ball_radius_mm, circles=circles, window=window,
                           stride=stride, out=out,
                           force=overwrite or deprecated(force, "--force", "--overwrite"),
                           labels=labels,
                           markers=tuple(marker or ()), progress=True)
    m, path = run(write_pattern_manifest, folder, opts)
    typer.echo(f"wrote {path}: {len(m.entries)} entries in {len(m.sessions)} session(s)")


def import_presses(
    src: Annotated[Path, typer.Argument(
        help="A gs_sdk calibration folder (catalog.csv, <ball>/<n>/gelsight.png and label.npz, "
             "background.png) or a Taxim data pack (.npz).")],
    out: Annotated[Path, typer.Option(
        help="Recordings folder to write recordings.json into (a gs_sdk folder's files stay "
             "where they are and may be SRC itself; a Taxim pack's frames are written here).")],
    mm_per_px: Annotated[float | None, number_option(
        low=1e-6, high=lim.MAX_MM_PER_PX,
        help="Scale in mm per pixel (default: --config's ppmm; Taxim: 0.1245).")] = None,
    config: Annotated[Path | None, typer.Option(
        help="gs_sdk sensor config (YAML) whose 'ppmm' key holds mm per pixel, e.g. "
             "gsmini.yaml.")] = None,
    ball_radius_mm: Annotated[float | None, number_option(
        low=1e-6, high=lim.MAX_MM,
        help="Taxim packs: ball radius in mm (default 2). A gs_sdk catalog gives each press's "
             "ball diameter.")] = None,
    sensor: Annotated[str | None, str_option(
        help="Sensor id (default: gelsight, or gelsight-taxim).")] = None,
    overwrite: Annotated[bool, typer.Option(
        "--overwrite", help="Replace an existing recordings.json.")] = False,
) -> None:
    """Turn ball-press calibration data from gs_sdk or Taxim into a recordings folder that
    `vtsbench calibrate` reads: circles, ball sizes, background and scale carried over.

    Example: [bold]vtsbench import-presses calib_dir --out recordings/mine --config gsmini.yaml[/]
    """
    from ..recordings.press_folders import import_presses as run_import

    def warn(msg: str) -> None:
        typer.echo(f"warning: {msg}", err=True)

    s = run(run_import, src, out, mm_per_px=mm_per_px, ball_radius_mm=ball_radius_mm,
            config=config, sensor=sensor, overwrite=overwrite, warn=warn)
    balls = ", ".join(f"{r:g}" for r in s.ball_radii_mm)
    scale = f"{s.mm_per_px:g} mm/px" if s.mm_per_px is not None else \
        "no scale (pass --mm-per-px to calibrate)"
    bg = "background" if s.background else "no background (calibrate --estimate-background)"
    typer.echo(f"wrote {s.path}: {s.presses} presses ({s.labelled} with labelled circles) "
               f"from a {s.layout} {'folder' if s.layout == 'gs_sdk' else 'pack'}; ball radius "
               f"{balls} mm; {scale}; {bg}")


def preview(
    folder: Annotated[Path, typer.Argument(help="Recordings folder.")],
    out: Annotated[Path, typer.Option("--out", help="PNG to write.")] = Path("preview.png"),
    n: Annotated[int, typer.Option("-n", "--n", min=1, max=200, help="Entries to show.")] = 12,
    seed: Annotated[int, typer.Option(
        min=0, max=lim.MAX_SEED, help="Which entries to pick (spread over kinds).")] = 0,
) -> None:
    """Write a contact sheet: frames with their labels and, for simulated data, the true depth."""
    from ..recordings.preview import write_preview

    shown = run(write_preview, folder, out, n=n, seed=seed)
    typer.echo(f"wrote {out} ({shown} entries)")


def stats(
    folder: Annotated[Path, typer.Argument(help="Recordings folder (with recordings.json).")],
    compare: Annotated[Path | None, typer.Option(
        help="A second recordings folder, measured the same way and shown side by side.")] = None,
    out: Annotated[Path | None, typer.Option(
        help="JSON file to write (schemas/stats.schema.json).")] = None,
    window: Annotated[int, typer.Option(
        min=2, max=lim.MAX_FRAMES, help="Frames per window (longer sequences are cut).")] = 8,
    max_windows: Annotated[int, typer.Option(
        min=1, max=100_000, help="Most windows measured per folder, spread evenly.")] = 200,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bar.")] = False,
) -> None:
    """Motion and appearance statistics per window: rigidity of the motion, rotation, strain,
    jerks, imprint texture, noise, contact made or lost (see docs/simulator.md).

    Example: [bold]vtsbench stats data/sim --compare recordings/lab --out stats.json[/]
    """
    from ..stats import run_stats
    from ..stats.table import print_stats

    folders = run(run_stats, folder, compare, out, window=window, max_windows=max_windows,
                  progress=not quiet)
    print_stats(folders, console())
    if out is not None:
        typer.echo(f"wrote {out}")


def collect(
    out: Annotated[Path, typer.Argument(help="Recordings folder to create (or add to, --append).")],
    source: Annotated[str, str_option(limit=lim.MAX_PATH_TEXT,
                                      help="Camera index (0, 1, ...) or video file.")],
    session: Annotated[str, str_option(help="Session id (one sitting of one sensor).")] = "s0",
    sensor: Annotated[str | None, str_option(
        help="Sensor id (new session; default 'unknown').")] = None,
    mm_per_px: Annotated[float | None, number_option(
        high=lim.MAX_MM_PER_PX, help="Scale, mm per pixel.")] = None,
    fps: Annotated[float | None, number_option(
        high=lim.MAX_FPS,
        help="Frame rate (default: as the source reports it).")] = None,
    mount_rotation: Annotated[float | None, number_option(
        low=-360.0, high=360.0,
        help="Mount: rotate stage motion CCW by this many degrees into the image (default 0).")
    ] = None,
    mount_mirror: Annotated[bool | None, typer.Option(
        "--mount-mirror/--no-mount-mirror",
        help="Mount: mirror stage x before rotating (default off).")] = None,
    background_frames: Annotated[int, typer.Option(
        min=0, max=1000,
        help="Leading no-contact frames: the background is their median; never cut into "
             "entries.")] = 10,
    background: Annotated[Path | None, typer.Option(
        help="Background image file for a new session, instead of the median.")] = None,
    kind: Annotated[Literal["sequence", "static", "press"], choice(
        help="sequence, static or press.")] = "sequence",
    window: Annotated[int, typer.Option(min=2, max=lim.MAX_FRAMES,
                                        help="Frames per sequence window.")] = 8,
    stride: Annotated[int | None, typer.Option(
        min=1, max=lim.MAX_STRIDE, help="Step between windows (default: --window).")] = None,
    every: Annotated[int, typer.Option(
        min=1, max=lim.MAX_STRIDE,
        help="static: keep every K-th frame; press: at most one frame per K.")] = 10,
    ball_radius_mm: Annotated[float | None, number_option(
        high=lim.MAX_MM,
        help="Indenter ball radius in mm (required for --kind press).")] = None,
    ball_radius: Annotated[float | None, typer.Option(
        "--ball-radius", callback=finite, hidden=True)] = None,
    contact_level: Annotated[float, number_option(
        low=0.0, high=255.0,
        help="press: gray levels of (blurred) change that count as contact.")] = 10.0,
    contact_area: Annotated[float, number_option(
        high=1.0,
        help="press: fraction of pixels in contact that makes a press frame.")] = 0.001,
    object_name: Annotated[str | None, str_option("--object", help="Object label.")] = None,
    take: Annotated[str | None, str_option(
        help="Take name (default: next free number).")] = None,
    max_frames: Annotated[int | None, typer.Option(
        min=1, max=lim.MAX_TAKE_FRAMES,
        help="Stop after this many frames (background included).")] = None,
    motion_log: Annotated[Path | None, typer.Option(
        help="CSV with columns t_s,x_mm,y_mm,z_mm (stage motion; z into the gel).")] = None,
    log_offset: Annotated[float, number_option(
        low=-1e6, high=1e6,
        help="Log time of frame 0 in seconds: frame i is at i / fps + offset.")] = 0.0,
    slip_threshold_mm: Annotated[float | None, number_option(
        high=lim.MAX_MM,
        help="Lateral motion (mm) over a window that makes a slip (default 0.05).")] = None,
    press_threshold_mm: Annotated[float | None, number_option(
        high=lim.MAX_MM,
        help="Indentation increase (mm) over a window that makes a press (default 0.05).")
    ] = None,
    append: Annotated[bool, typer.Option(
        "--append", help="Add a session or take to an existing OUT.")] = False,
    overwrite: Annotated[bool, typer.Option(
        "--overwrite", help="Replace OUT if it exists.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bar.")] = False,
) -> None:
    """Record a camera or a video file into a recordings folder, labelled from a motion log.

    Example: [bold]vtsbench collect rec --source take.mp4 --sensor gsmini --motion-log log.csv[/]
    """
    from ..recordings.collect import CollectOptions
    from ..recordings.collect import collect as run_collect

    opts = CollectOptions(
        source=source, session=session, sensor=sensor, mm_per_px=mm_per_px, fps=fps,
        mount_rotation_deg=mount_rotation, mount_mirror=mount_mirror,
        background_frames=background_frames, background=background, kind=kind, window=window,
        stride=stride, every=every,
        ball_radius_mm=ball_radius_mm if ball_radius_mm is not None
        else deprecated(ball_radius, "--ball-radius", "--ball-radius-mm"),
        contact_level=contact_level,
        contact_area=contact_area, object=object_name, take=take, max_frames=max_frames,
        motion_log=motion_log, log_offset_s=log_offset, slip_threshold_mm=slip_threshold_mm,
        press_threshold_mm=press_threshold_mm, append=append, overwrite=overwrite)
    res = run(run_collect, out, opts, progress=not quiet)
    if res.stopped:
        typer.echo("stopped by Ctrl-C: kept the entries completed so far", err=True)
    typer.echo(f"wrote {len(res.entries)} {kind} entries to {out} (session {res.session}, "
               f"take {res.take}; {res.frames_read} frames read)")
