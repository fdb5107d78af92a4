"""The `vtsbench` command. Start-up imports only typer; every command imports its work lazily."""

from __future__ import annotations

import contextlib
import os
import sys
from pathlib import Path
from typing import Annotated, Any, Literal

import typer

from . import limits as lim
from .cli_help import install as _install_help

_install_help()

app = typer.Typer(
    name="vtsbench",
    help="Benchmark toolkit for visuo-tactile sensing: recordings -> calibrated RGB-D datasets "
         "-> loaders, baselines and scoring.",
    no_args_is_help=True,
    rich_markup_mode="rich",
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _version(value: bool) -> None:
    """`vtsbench --version`: the installed package's version."""
    if value:
        from importlib.metadata import version

        typer.echo(f"vtsbench {version('vtsbench')}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[bool, typer.Option(
        "--version", callback=_version, is_eager=True,
        help="Print the version and exit.")] = False,
) -> None:
    """Options of `vtsbench` itself (the app's help text is the Typer's)."""


def _choice(**kw):
    """An option whose annotation is a Literal of its values: --help lists them, the shell
    completes them, and any other value is a one-line usage error naming them (exit 2)."""
    return typer.Option(**kw)


def _open_choice(*values: str, **kw):
    """An option with usual values (listed in --help and completed) that takes others too:
    a device is auto, cpu, cuda or cuda:N."""
    def complete(incomplete: str) -> list[str]:
        return [v for v in values if v.startswith(incomplete)]

    return typer.Option(metavar="[" + "|".join(values) + "|...]", autocompletion=complete,
                        **kw)


def _deprecated(value: Any, old: str, new: str) -> Any:
    """The value of a hidden old spelling of an option, with a one-line note when it is used."""
    if value not in (None, False):
        typer.echo(f"note: {old} is deprecated; use {new}", err=True)
    return value


def _fail(err: Exception, code: int = 2) -> None:
    """Print a user error as one line and exit (no traceback): control characters escaped and
    over-long values cut, whatever the error quotes (a path with a newline, a huge name)."""
    from .errors import MAX_MESSAGE, MAX_PATH, one_line

    typer.echo(f"error: {one_line(err, MAX_MESSAGE + MAX_PATH + 2)}", err=True)
    raise typer.Exit(code)


def _os_error(err: OSError) -> Exception:
    """An OSError as a one-line user error naming its file; a full disk met by a library's own
    write names none, so the output the command was writing (its --out, OUT or --root) is named."""
    import errno

    from .errors import VtsError

    reason = err.strerror or str(err)
    if err.filename is not None:
        f = err.filename
        return VtsError(reason, os.fsdecode(f) if isinstance(f, bytes) else f)
    if err.errno in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT, errno.EROFS, errno.EIO):
        try:  # typer >= 0.2x carries its own click
            from typer._click.globals import get_current_context
        except ImportError:  # pragma: no cover - older typer on the click package
            from click import get_current_context
        ctx = get_current_context(silent=True)
        params = ctx.params if ctx is not None else {}
        out = next((params[k] for k in ("out", "root") if params.get(k) is not None), None)
        return VtsError(f"cannot write ({reason})", out)
    return VtsError(reason)


def _run(fn, *args, **kwargs):
    """Run a command body, turning user errors (VtsError) into a one-line message and exit 2."""
    from .errors import VtsError

    try:
        return fn(*args, **kwargs)
    except VtsError as e:
        _fail(e)
    except OSError as e:  # an output path that is a file or a folder, a name over 255 bytes...
        _fail(_os_error(e))
    except KeyboardInterrupt:
        typer.echo("interrupted: nothing was written under the output's final name", err=True)
        raise typer.Exit(130) from None


def _console() -> Any:
    """A rich Console on stdout: the terminal's width, or 160 columns in a pipe or a log (no
    COLUMNS set), where rich would assume 80 and cut a table's names with an ellipsis."""
    from rich.console import Console

    console = Console(highlight=False)
    if not console.is_terminal and "COLUMNS" not in os.environ:
        console.width = 160
    return console


def _report(problems: list[str], warnings: list[str], summary: str) -> None:
    """Print warnings, problems (one line each) and a summary; exit 1 if there is a problem."""
    from rich.markup import escape

    console = _console()
    for w in warnings:
        console.print(f"[yellow]warning[/] {escape(w)}", soft_wrap=True)
    for p in problems:
        console.print(f"[red]problem[/] {escape(p)}", soft_wrap=True)
    console.print(escape(summary))
    if problems:
        raise typer.Exit(1)


def _finite(value: float | None) -> float | None:
    """Option callback: NaN and infinity are refused where a number is expected."""
    import math

    if value is not None and not math.isfinite(value):
        raise typer.BadParameter(f"expected a finite number, got {value}")
    return value


def _text(limit: int):
    """Option callback: a string (or each of a repeated option's strings) of at most LIMIT
    characters; the help text states the bound."""
    def check(value: Any) -> Any:
        for v in value if isinstance(value, (list, tuple)) else (value,):
            if v is not None and len(v) > limit:
                raise typer.BadParameter(f"{len(v)} characters; at most {limit}")
        return value

    return check


def _str_option(*decls: str, help: str, limit: int = lim.MAX_NAME, **kw: Any) -> Any:
    """An option taking a string of at most LIMIT characters, the bound in its help."""
    return typer.Option(*decls, callback=_text(limit), help=f"{help} At most {limit} characters.",
                        **kw)


def _str_argument(*, help: str, limit: int = lim.MAX_PATH_TEXT, **kw: Any) -> Any:
    """An argument taking a string of at most LIMIT characters, the bound in its help."""
    return typer.Argument(callback=_text(limit), help=f"{help} At most {limit} characters.",
                          **kw)


def _finite_in(low: float | None, high: float | None):
    """Option callback: a finite number (NaN and infinity refused as by `_finite`) from LOW to
    HIGH; a bound left None is the library's to check (its message names the file)."""
    def check(value: float | None) -> float | None:
        _finite(value)
        if value is not None and ((low is not None and value < low)
                                  or (high is not None and value > high)):
            raise typer.BadParameter(f"expected a number {_bounds(low, high)}, got {value:g}")
        return value

    return check


def _bounds(low: float | None, high: float | None) -> str:
    if low is None:
        return f"of at most {high:g}"
    return f"from {low:g} to {high:g}" if high is not None else f"of at least {low:g}"


def _number_option(*decls: str, help: str, low: float | None = None,
                   high: float | None = None, **kw: Any) -> Any:
    """An option taking a finite number within its bounds, stated in its help."""
    bound = _bounds(low, high).removeprefix("of ")
    return typer.Option(*decls, callback=_finite_in(low, high),
                        help=f"{help} {bound[0].upper()}{bound[1:]}.", **kw)


def _parse_size(text: str) -> tuple[int, int]:
    """--size HxW as (height, width); the bounds are the library's (simulate checks them)."""
    from .errors import one_line

    try:
        h, w = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise typer.BadParameter(f"expected HxW such as 480x640, got {one_line(repr(text), 40)}"
                                 ) from None
    if h < 1 or w < 1:
        raise typer.BadParameter("height and width must be positive")
    return h, w


@app.command()
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
        callback=_finite,
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
    gel: Annotated[Literal["markers", "plain"] | None, _choice(
        help="Generator 2: the sensor's gel, 'markers' (a printed marker grid) or 'plain' "
             "(default); every session of the folder wears it.")] = None,
) -> None:
    """Write a synthetic recordings folder with exact ground-truth depth and gradients.

    Example: [bold]vtsbench simulate data/sim --seed 0 --static 30 --sequences 30 --presses 20[/]
    """
    from .sim.simulate import simulate as run_sim

    m = _run(run_sim, out, seed=seed, n_static=static, n_sequences=sequences, n_presses=presses,
             n_objects=objects, size=_parse_size(size), frames=frames, n_sessions=sessions,
             mm_per_px=mm_per_px, workers=workers, overwrite=overwrite, progress=not quiet,
             generator=generator, gel=gel)
    typer.echo(f"wrote {len(m.entries)} entries in {len(m.sessions)} sessions to {out}")


@app.command()
def benchmark(
    name: Annotated[Literal["v2", "v2-demo"], typer.Argument(
        help="Benchmark: v2 (the published one: 3,600 sequences, 3,000 static frames) or "
             "v2-demo (the same generator at 360 sequences, 300 static frames).")],
    out: Annotated[Path, typer.Argument(
        help="Folder to make: OUT/recordings (with its calibration) and OUT/dataset.")],
    seed: Annotated[int | None, typer.Option(
        min=0, max=lim.MAX_SEED,
        help="Another seed than the benchmark's own (a check on data nobody tuned on).")] = None,
    workers: Annotated[int, typer.Option(min=1, max=lim.MAX_WORKERS,
                                         help="Worker processes.")] = 2,
    overwrite: Annotated[bool, typer.Option(
        "--overwrite", help="Make everything again, replacing OUT's recordings and dataset.")
    ] = False,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bars.")] = False,
) -> None:
    """Make a named, versioned benchmark: simulate, calibrate and build it in one go.

    Resumable: rerun the same command after an interruption; finished steps and shards are
    kept. Example: [bold]vtsbench benchmark v2 data/v2 --workers 2[/]
    """
    from .sim.benchmark import make_benchmark

    made = _run(make_benchmark, name, out, seed=seed, workers=workers, overwrite=overwrite,
                progress=not quiet, log=lambda m: typer.echo(m, err=m.startswith("warning")))
    _print_build(made["build"])
    s = made["seconds"]
    typer.echo(f"benchmark {name} (seed {made['config']['seed']}, dataset version "
               f"{made['config']['dataset_version']}) in {out}: simulate {s['simulate']:.0f} s, "
               f"calibrate {s['calibrate']:.0f} s, build {s['build']:.0f} s")


@app.command()
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

    from .recordings.check import check_folder

    report = _run(check_folder, folder, deep=deep, workers=workers, labels=labels,
                  progress=True)
    _report(report.problems, report.warnings,
            f"{report.n_entries} entries, {report.n_frames} frames checked: "
            f"{len(report.problems)} problem(s), {len(report.warnings)} warning(s)")


@app.command()
def manifest(
    folder: Annotated[Path, typer.Argument(help="Folder of existing files to describe.")],
    pattern: Annotated[str, _str_option(
        limit=lim.MAX_PATH_TEXT,
        help="File-name pattern relative to FOLDER, e.g. '{object}_{take}.mov'. Fields: object, "
             "take, session, state, direction; '{name:d}' matches digits only; fields match "
             "greedily from the left; '/' matches sub-folders.")],
    kind: Annotated[Literal["static", "sequence", "press"] | None, _choice(
        help="static, sequence or press (default: sequence for videos and image folders, "
             "static for images).")] = None,
    sensor: Annotated[str, _str_option(help="Sensor id.")] = "unknown",
    session: Annotated[str, _str_option(
        help="Session id when the pattern has no {session}.")] = "s0",
    mm_per_px: Annotated[float | None, _number_option(
        high=lim.MAX_MM_PER_PX,
        help="mm per pixel, if known.")] = None,
    fps: Annotated[float | None, _number_option(
        high=lim.MAX_FPS,
        help="Frame rate (default: read from videos).")] = None,
    background: Annotated[str | None, _str_option(
        limit=lim.MAX_PATH_TEXT, help="No-contact frame, relative to FOLDER.")] = None,
    ball_radius_mm: Annotated[float | None, _number_option(
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
    marker: Annotated[list[str] | None, _str_option(
        limit=lim.MAX_PATH_TEXT,
        help="FILE:FIELD=VALUE: entries with FILE in their folder (or a folder above) get the "
             "label, e.g. slip.txt:state=slip; '!FILE:...' when FILE is absent. Repeatable.")
    ] = None,
) -> None:
    """Write recordings.json for a folder of existing files, matched by a file-name pattern.

    Example: [bold]vtsbench manifest videos --pattern '{object}_{take}.mov' --sensor gsmini[/]
    """
    from .recordings.importer import ManifestOptions, write_pattern_manifest

    opts = ManifestOptions(pattern=pattern, kind=kind, sensor=sensor, session=session,
                           mm_per_px=mm_per_px, fps=fps, background=background,
                           ball_radius_mm=ball_radius_mm, circles=circles, window=window,
                           stride=stride, out=out,
                           force=overwrite or _deprecated(force, "--force", "--overwrite"),
                           labels=labels,
                           markers=tuple(marker or ()), progress=True)
    m, path = _run(write_pattern_manifest, folder, opts)
    typer.echo(f"wrote {path}: {len(m.entries)} entries in {len(m.sessions)} session(s)")


@app.command()
def preview(
    folder: Annotated[Path, typer.Argument(help="Recordings folder.")],
    out: Annotated[Path, typer.Option("--out", help="PNG to write.")] = Path("preview.png"),
    n: Annotated[int, typer.Option("-n", "--n", min=1, max=200, help="Entries to show.")] = 12,
    seed: Annotated[int, typer.Option(
        min=0, max=lim.MAX_SEED, help="Which entries to pick (spread over kinds).")] = 0,
) -> None:
    """Write a contact sheet: frames with their labels and, for simulated data, the true depth."""
    from .preview import write_preview

    shown = _run(write_preview, folder, out, n=n, seed=seed)
    typer.echo(f"wrote {out} ({shown} entries)")


@app.command()
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
    from .stats import run_stats
    from .stats.table import print_stats

    folders = _run(run_stats, folder, compare, out, window=window, max_windows=max_windows,
                   progress=not quiet)
    print_stats(folders, _console())
    if out is not None:
        typer.echo(f"wrote {out}")


@app.command()
def build(
    recordings: Annotated[Path, typer.Argument(help="Recordings folder (with recordings.json).")],
    out: Annotated[Path, typer.Argument(help="Dataset folder to create.")],
    calibration: Annotated[Path | None, typer.Option(
        help="Calibration file (default: RECORDINGS/calibration.safetensors, as written by "
             "`vtsbench calibrate RECORDINGS --out RECORDINGS/calibration.safetensors`).")
    ] = None,
    solver: Annotated[Literal["dct", "dst", "masked"], _choice(
        help="Depth solver: dct, dst or masked.")] = "dct",
    no_depth: Annotated[bool, typer.Option(
        "--no-depth", help="RGB only: no depth or contact arrays, no calibration needed (for "
                           "sensors without calibration presses).")] = False,
    frames: Annotated[int, typer.Option(min=1, max=lim.MAX_FRAMES,
                                        help="Frames per slip sample (T).")] = 8,
    workers: Annotated[int, typer.Option(
        min=1, max=lim.MAX_WORKERS,
        help="Worker processes (or Dask workers with --scheduler local).")] = 1,
    scheduler: Annotated[str | None, _str_option(
        limit=lim.MAX_PATH_TEXT,
        help="Dask scheduler address (tcp://host:8786), or 'local' for a LocalCluster of "
             "--workers processes. OUT must be on a file system the workers share.")] = None,
    skip_bad: Annotated[bool, typer.Option(
        "--skip-bad", help="Leave bad recordings out (listed in meta/build_report.json) instead of "
             "stopping.")] = False,
    overwrite: Annotated[bool, typer.Option(
        "--overwrite", help="Replace OUT if it exists.")] = False,
    dataset_version: Annotated[str, _str_option(
        limit=lim.MAX_VERSION,
        help="The dataset's version (semantic version of its content; `vtsbench --version` is "
             "the program's).")] = "1.0.0",
    version: Annotated[str | None, typer.Option("--version", hidden=True)] = None,
    compression_level: Annotated[int, typer.Option(
        min=0, max=22, help="zstd level of the arrays; 0 stores them uncompressed.")] = 3,
    seed: Annotated[int, typer.Option(min=0, max=lim.MAX_SEED,
                                      help="Seed of the split files.")] = 0,
    shard_mb: Annotated[float, _number_option(
        low=lim.MIN_SHARD_MB, high=lim.MAX_SHARD_MB,
        help="Target uncompressed RGB shard size in MB (whole samples per shard).")] = 32.0,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bars.")] = False,
    holdout_objects: Annotated[Path | None, typer.Option(
        help="File of object names, one a line: adds the split scheme given_objects, test = "
             "exactly these objects, val = other whole objects.")] = None,
    split_file: Annotated[list[Path] | None, typer.Option(
        help="A split scheme of your own (JSON in schemas/split.schema.json); repeatable.")
    ] = None,
) -> None:
    """Build an RGB-D dataset (Zarr + parquet index + splits + card) from a recordings folder
    (RGB only with --no-depth).

    Atomic and resumable: writes into .OUT.partial beside OUT; rerun the same command after an
    interruption and finished shards are kept. Example:
    [bold]vtsbench build data/rec data/ds --workers 2[/]
    """
    from rich.console import Console

    from .dataset.build import BuildOptions
    from .dataset.build import build as run_build

    console = Console(stderr=True, highlight=False)
    opts = BuildOptions(calibration=calibration, solver=solver, depth=not no_depth,
                        frames=frames, workers=workers,
                        scheduler=scheduler, skip_bad=skip_bad, overwrite=overwrite,
                        version=_deprecated(version, "build --version", "--dataset-version")
                        or dataset_version, compression_level=compression_level, seed=seed,
                        shard_mb=shard_mb, progress=not quiet,
                        holdout_objects=holdout_objects, split_files=tuple(split_file or ()))
    res = _run(run_build, recordings, out, opts, log=lambda m: console.print(m, soft_wrap=True,
                                                                       markup=False))
    _print_build(res)


def _print_build(res) -> None:
    """The skipped entries and a summary table of a build."""
    from rich.markup import escape
    from rich.table import Table

    from .dataset.summary import human

    console = _console()
    for w in res.warnings:
        console.print(f"[yellow]warning[/] {escape(w)}", soft_wrap=True)
    for eid, why in res.skipped.items():
        console.print(f"[yellow]skipped[/] {escape(f'{eid}: {why}')}", soft_wrap=True)
    for why in res.splits_skipped.values():
        console.print(f"[yellow]split not made[/] {escape(why)}", soft_wrap=True)
    t = Table(title=escape(f"built {res.out}"), title_justify="left")
    for c in ("kind", "samples", "frames", "shards"):
        t.add_column(c, justify="left" if c == "kind" else "right")
    for kind in ("static", "slip"):
        t.add_row(kind, str(res.samples[kind]), str(res.frames[kind]), str(res.shards[kind]))
    console.print(t)
    frames, size = sum(res.frames.values()), human(sum(res.bytes_on_disk.values()))
    console.print(f"{frames} frames in {res.seconds:.1f} s ({frames / max(res.seconds, 1e-9):.0f}"
                  f" frames/s); shards built {res.shards_built}, kept from a partial build "
                  f"{res.shards_kept}; {len(res.skipped)} entries skipped; splits: "
                  f"{', '.join(res.splits) or 'none'}; {size} on disk")


@app.command()
def info(
    dataset: Annotated[str, _str_argument(
        help="Dataset folder (made by vtsbench build), or a URL as vtsbench.load takes "
             "(file://, http(s)://, s3://...).")],
) -> None:
    """Summarise a dataset: samples per object, state, direction and split part; sizes on disk;
    versions and checksum."""

    from .dataset.summary import render, summarise

    render(_run(summarise, dataset), _console())


@app.command()
def verify(
    dataset: Annotated[str, _str_argument(
        help="Dataset folder (made by vtsbench build), or a URL as vtsbench.load takes "
             "(file://, http(s)://, s3://...; a remote one is fetched to a temporary "
             "folder).")],
    quick: Annotated[bool, typer.Option(
        "--quick",
        help="Skip decoding every chunk (checksums, schema, index, splits and shapes only).")
    ] = False,
) -> None:
    """Check a dataset: every file's sha256, info.json and split schemas, index and array shapes,
    split leaks, and decode every chunk; exit 1 on any problem."""

    from .dataset.verify import verify as run_verify

    report = _run(run_verify, dataset, decode=not quick, progress=True)
    _report(report.problems, report.warnings, f"{report.files} files, {report.samples} samples, "
            f"{report.shards} shards checked: {len(report.problems)} problem(s)")


@app.command("export-hf")
def export_hf(
    dataset: Annotated[Path, typer.Argument(help="Dataset folder (made by vtsbench build).")],
    workers: Annotated[int, typer.Option(min=1, max=lim.MAX_WORKERS,
                                         help="Threads encoding the PNGs.")] = 1,
    license: Annotated[str, _str_option(
        help="License id for the card (a Hub license id: cc-by-4.0, mit, other...).")
    ] = "unknown",
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bar.")] = False,
) -> None:
    """Write every sample as parquet under DATASET/hf/ for Hugging Face `datasets`: one config
    per split scheme (slip_unseen_objects, slip_seen, static_sessions, ...), labels as
    ClassLabel, RGB as PNG images, depth in mm; rewrites the card and records the files in
    meta/info.json. The new version is made beside DATASET (.DATASET.hf.partial) and swapped
    in whole: an interrupted export leaves DATASET as it was and a rerun resumes.
    Example: [bold]vtsbench export-hf data/ds --license cc-by-4.0[/]
    """

    from .dataset.hub import export_hf as run_export
    from .dataset.summary import human

    res = _run(run_export, dataset, workers=workers, license=license, progress=not quiet)
    lay = res.layout
    n = sum(f.rows for fs in lay.files.values() for f in fs)
    files = sum(len(fs) for fs in lay.files.values())
    _console().print(
        f"{n} samples in {files} parquet files ({human(lay.nbytes())}) in {res.seconds:.1f} s"
        f"{f' ({res.kept} kept from an interrupted export)' if res.kept else ''}; "
        f"configs: {', '.join(lay.configs)}")


@app.command()
def push(
    dataset: Annotated[Path, typer.Argument(help="Dataset folder (made by vtsbench build).")],
    repo_id: Annotated[str, _str_argument(limit=lim.MAX_NAME,
                                          help="Hub dataset repository, e.g. my-lab/tactile.")],
    dry_run: Annotated[bool, typer.Option(
        "--dry-run", help="List what would be uploaded and stop (no network).")] = False,
    zarr: Annotated[bool, typer.Option(
        help="Upload the Zarr arrays (data/) too, so vtsbench.load reads the repository; "
             "--no-zarr uploads the parquet copy, index, splits and card only.")] = True,
    private: Annotated[bool, typer.Option(
        "--private", help="Create the repository private.")] = False,
    revision: Annotated[str | None, _str_option(help="Branch to push to.")] = None,
) -> None:
    """Upload a verified dataset to the Hugging Face Hub (run `vtsbench export-hf` first for
    the viewer and `datasets.load_dataset`). Example:
    [bold]vtsbench push data/ds my-lab/tactile --dry-run[/]
    """

    from .dataset.push import push as run_push
    from .dataset.push import push_plan
    from .dataset.summary import human

    console = _console()
    plan = _run(push_plan, dataset, zarr, repo_id)
    if not plan.has_hub_copy:
        console.print("[yellow]warning[/] no hf/ folder: run `vtsbench export-hf` first for "
                      "the Hub viewer and datasets.load_dataset configs", soft_wrap=True)
    if dry_run:
        for rel, size in plan.files:
            console.print(f"{human(size):>10}  {rel}", soft_wrap=True)
        console.print(f"dry run: would upload {len(plan.files)} files ({human(plan.nbytes)}) "
                      f"to datasets/{repo_id}" + (f"; leaving out {len(plan.left_out)} Zarr "
                                                  "files" if plan.left_out else ""))
        return
    url = _run(run_push, dataset, repo_id, zarr=zarr, private=private, revision=revision)
    console.print(f"uploaded {len(plan.files)} files ({human(plan.nbytes)}): {url}")


@app.command()
def calibrate(
    recordings: Annotated[Path, typer.Argument(help="Recordings folder with ball presses.")],
    out: Annotated[Path, typer.Option("--out", help="Calibration file to write (.safetensors).")],
    method: Annotated[Literal["lut", "poly", "mlp"], _choice(
        help="lut (fast lookup), poly (polynomial) or mlp (small network, needs torch).")
    ] = "poly",
    holdout: Annotated[int | None, typer.Option(
        min=0, max=lim.MAX_COUNT,
        help="Presses kept out of training and scored (default: a fifth).")] = None,
    seed: Annotated[int, typer.Option(
        min=0, max=lim.MAX_SEED, help="Seed of the hold-out choice, sampling, mlp.")] = 0,
    mm_per_px: Annotated[float | None, _number_option(
        high=100.0,
        help="Scale in mm per pixel (default: from the recordings).")] = None,
    background: Annotated[Path | None, typer.Option(
        help="No-contact image (default: the sessions' backgrounds).")] = None,
    estimate_background: Annotated[bool, typer.Option(
        "--estimate-background",
        help="Use the per-pixel median of the press frames as the background.")] = False,
    report: Annotated[Path | None, typer.Option(
        help="Report folder (default: FILE.report beside the calibration).")] = None,
    solver: Annotated[Literal["dct", "dst", "masked"], _choice(
        help="Poisson solver scoring the held-out presses: dct, dst or masked.")] = "dct",
    device: Annotated[Literal["auto", "cpu", "cuda"], _choice(
        help="mlp training device: auto (CUDA when present), cpu or cuda.")] = "auto",
    bins: Annotated[int | None, typer.Option(
        min=2, max=256,
        help="lut: colour bins per channel (32); bins^3 x cells^2 at most 2^26.")] = None,
    cells: Annotated[int | None, typer.Option(
        min=1, max=64, help="lut: spatial cells per side (2).")] = None,
    degree: Annotated[int | None, typer.Option(
        min=1, max=8, help="poly: colour degree (3).")] = None,
    pos_degree: Annotated[int | None, typer.Option(
        min=0, max=4, help="poly, mlp: degree of the position polynomial (2).")] = None,
    width: Annotated[int | None, typer.Option(
        min=1, max=4096, help="mlp: units per hidden layer (32).")] = None,
    depth: Annotated[int | None, typer.Option(min=1, max=32, help="mlp: hidden layers (3).")
                     ] = None,
    epochs: Annotated[int | None, typer.Option(
        min=1, max=100_000, help="mlp: training epochs (40).")] = None,
    circles: Annotated[Literal["label", "detect"], _choice(
        help="label: use labelled circles, detect the others; detect: detect every circle "
             "(labels only compared, in report.json).")] = "label",
    markers: Annotated[Literal["auto", "off"], _choice(
        help="auto: a marker grid found in the background is left out of the fit and filled "
             "before integration; off: never.")] = "auto",
    rim_cv: Annotated[bool, typer.Option(
        "--rim-cv", help="Choose the rim shrink by cross-validation over the training presses "
                         "(16 extra fits).")] = False,
) -> None:
    """Fit a colour-to-gradient calibration from ball presses, score held-out presses.

    Example: [bold]vtsbench calibrate rec --out sensor.safetensors --method mlp --holdout 6[/]
    """
    import time

    def work() -> None:
        from .depth.calibration import calibrate as run_calibrate
        from .depth.calibration import save_calibration
        from .depth.report import write_report
        from .errors import VtsError

        given = {"bins": bins, "cells": cells, "degree": degree, "pos_degree": pos_degree,
                 "width": width, "depth": depth, "epochs": epochs}
        allowed = {"lut": {"bins", "cells"}, "poly": {"degree", "pos_degree"},
                   "mlp": {"width", "depth", "epochs", "pos_degree"}}.get(method, set())
        wrong = sorted(k for k, v in given.items() if v is not None and k not in allowed)
        if wrong:
            opts = ", ".join("--" + k.replace("_", "-") for k in wrong)
            raise VtsError(f"{opts} does not apply to --method {method}")
        if solver not in ("dct", "dst", "masked"):
            raise VtsError(f"unknown solver {solver!r} (use dct, dst or masked)")
        t0 = time.perf_counter()
        run = run_calibrate(recordings, method=method, holdout=holdout, seed=seed,
                            mm_per_px=mm_per_px, background=background,
                            estimate_background=estimate_background, solver=solver,
                            device=device, options={k: v for k, v in given.items()
                                                    if v is not None},
                            log=lambda m: typer.echo(m, err=m.startswith("warning")),
                            circles=circles, markers=markers, rim_cv=rim_cv)
        save_calibration(run.calibration, out)
        folder = report if report is not None else out.with_name(out.name + ".report")
        png, _ = write_report(run, folder)
        fit = run.calibration.fit
        for r in run.held_out:
            e = r.errors
            typer.echo(f"  {r.press.id}: gradient RMSE {e['gradient_rmse']:.4f}, plane-aligned "
                       f"RMSE {e['plane_aligned_rmse_mm']:.4f} mm, contact RMSE "
                       f"{e['contact_rmse_mm']:.4f} mm, peak error "
                       f"{e['peak_depth_error_mm']:+.4f} mm ({r.reference})")
        if run.held_out:
            m = fit["holdout_mean"]

            def mm(k: str, sign: str = "") -> str:
                v = m.get(k)
                return "n/a" if v is None else f"{v:{sign}.4f} mm"

            typer.echo(f"held-out mean over {len(run.held_out)} presses: plane-aligned RMSE "
                       f"{mm('plane_aligned_rmse_mm')}, contact RMSE {mm('contact_rmse_mm')}, "
                       f"peak error {mm('peak_depth_error_mm', '+')}, gradient RMSE "
                       f"{m['gradient_rmse']:.4f}")
            parts = [f"{s} {mm(s + '_contact_rmse_mm')}, {mm(s + '_peak_depth_error_mm', '+')}, "
                     f"{mm(s + '_min_depth_mm', '+')}, {mm(s + '_border_abs_mm')}"
                     for s in ("dct", "dst", "masked")]
            typer.echo("  by solver (contact RMSE, peak error, lowest depth, mean |depth| on the "
                       "border): " + "; ".join(parts)
                       + " (masked: zero outside the contact, for absolute depth)")
        caveat = "".join(
            f"; {len(ids)} press(es) {what} ({', '.join(ids[:8])}{', ...' if len(ids) > 8 else ''}"
            f", see report.json)" for ids, what in ((run.dropped, "dropped"),
                                                    (run.doubted, "doubted"),
                                                    (run.retried, "with a circle detected again"))
            if ids)
        typer.echo(f"wrote {out} ({method}, {run.calibration.n_presses} training presses) and "
                   f"{png} in {time.perf_counter() - t0:.1f} s{caveat}")

    _run(work)


@app.command()
def depth(
    images: Annotated[list[str], _str_argument(
        help="Images, folders of images, videos or globs such as 'takes/*.mp4' (quoted).")],
    calibration: Annotated[Path, typer.Option(help="Calibration file from `vtsbench calibrate`.")],
    solver: Annotated[Literal["dct", "dst", "masked"], _choice(
        help="Poisson solver: dct, dst or masked.")] = "dct",
    out: Annotated[Path, typer.Option(
        "--out", help="Output folder for <name>.npy (float32 mm) and <name>.png; with several "
                      "inputs, a folder's or video's maps go to OUT/<its name>/.")
    ] = Path("depth"),
    device: Annotated[Literal["auto", "cpu", "cuda", "numpy"], _choice(
        help="auto (CUDA when present, else numpy), cpu or cuda (torch), numpy.")] = "auto",
    batch: Annotated[int, typer.Option(min=1, max=1024, help="Frames per step.")] = 8,
    range_: Annotated[str | None, _str_option(
        "--range", help="Fixed colour scale of the PNGs, MIN,MAX in mm (e.g. -0.2,1.5), the "
                        "same for every frame (default: each frame's own; negative depth is "
                        "drawn in red).")] = None,
) -> None:
    """Reconstruct depth (mm) from tactile images with a calibration.

    Example: [bold]vtsbench depth frames/ 'takes/*.mp4' --calibration sensor.safetensors
    --out depth/ --range -0.2,1.5[/]
    """
    from .depth.reconstruct import depth_paths, parse_range

    def work() -> int:
        return depth_paths(images, calibration, out, solver=solver,
                           device=None if device == "numpy" else device, batch=batch,
                           value_range=parse_range(range_),
                           log=lambda m: typer.echo(m, err=True))

    n = _run(work)
    typer.echo(f"wrote {n} depth map(s) to {out}")


@app.command("eval")
def eval_(
    submission: Annotated[Path, typer.Argument(help="Predictions: CSV or parquet.")],
    dataset: Annotated[Path, typer.Option(help="Dataset folder (made by vtsbench build).")],
    split: Annotated[str, _str_option(limit=lim.MAX_SPLIT,
                                      help="Split scheme, e.g. unseen_objects or seen.")],
    part: Annotated[str, _str_option(limit=lim.MAX_SPLIT,
                                     help="Part of the split to score.")] = "test",
    out: Annotated[Path | None, typer.Option(
        help="Write metrics.json, report.md and confusion-matrix PNGs here.")] = None,
    meta: Annotated[Path | None, typer.Option(
        help="Metadata JSON (default: SUBMISSION.meta.json beside it).")] = None,
    figures: Annotated[bool, typer.Option(help="Write the PNGs (with --out).")] = True,
) -> None:
    """Validate a submission, score it and print a short table; exit 2 listing every problem.

    Example: [bold]vtsbench eval preds.csv --dataset data/ds --split unseen_objects --out ev[/]
    """
    from .evaluation.report import SUMMARY_HEAD, evaluate, summary_rows

    doc, _, _ = _run(evaluate, submission, dataset, split, part, out=out, meta=meta,
                     figures=figures)
    _print_rows(f"{doc['submission']['method']} on {doc['split']}/{doc['part']} "
                f"(metric version {doc['metric_version']})", SUMMARY_HEAD, summary_rows(doc))
    d = doc["tasks"].get("direction")
    if d:
        s = d["summary"]
        e2e, mae = s["end_to_end_accuracy"]["mean"], s["mean_abs_angular_error_deg"]["mean"]
        typer.echo(f"direction: end to end {'-' if e2e is None else f'{100 * e2e:.2f} %'}, "
                   f"within one bin {100 * (s['within_one_bin']['mean'] or 0):.2f} %, "
                   f"angular error {'-' if mae is None else f'{mae:.1f}'} deg")
    if out is not None:
        typer.echo(f"wrote {out}/metrics.json and report.md")


def _print_rows(title: str, head: tuple[str, ...], rows: list[tuple[str, ...]]) -> None:
    from rich.markup import escape
    from rich.table import Table

    t = Table(title=escape(title), title_justify="left")
    for i, c in enumerate(head):
        t.add_column(c, justify="left" if i in (0, len(head) - 1) else "right")
    for r in rows:
        t.add_row(*(escape(x) for x in r))
    _console().print(t)


leaderboard_app = typer.Typer(help="Leaderboards in leaderboards/<dataset>/<split>/: add, "
                                   "render, rescore.", no_args_is_help=True)
app.add_typer(leaderboard_app, name="leaderboard")
_ROOT = Annotated[Path, typer.Option("--root", help="Leaderboards folder.")]


@leaderboard_app.command("add")
def leaderboard_add(
    submission: Annotated[Path, typer.Argument(help="Predictions: CSV or parquet.")],
    dataset: Annotated[Path, typer.Option(help="Dataset folder.")],
    split: Annotated[str, _str_option(limit=lim.MAX_SPLIT, help="Split scheme.")],
    part: Annotated[str, _str_option(limit=lim.MAX_SPLIT, help="Part of the split.")] = "test",
    meta: Annotated[Path | None, typer.Option(help="Metadata JSON.")] = None,
    root: _ROOT = Path("leaderboards"),
    overwrite: Annotated[bool, typer.Option(
        "--overwrite", help="Replace the same submission's entry.")] = False,
    replace: Annotated[bool, typer.Option("--replace", hidden=True)] = False,
) -> None:
    """Score a submission and store it (predictions included) as a leaderboard entry."""
    from .evaluation.leaderboard import add, render

    replace = overwrite or _deprecated(replace, "--replace", "--overwrite")
    path = _run(add, submission, dataset, split, part, root=root, meta=meta, replace=replace)
    _run(render, root)
    typer.echo(f"added {path}; rendered {path.parent / 'leaderboard.md'}")


@leaderboard_app.command("render")
def leaderboard_render(root: _ROOT = Path("leaderboards")) -> None:
    """Write leaderboard.md (summary with the paper's reference row, per-task detail) in every
    dataset/split folder and print them."""
    from .evaluation.leaderboard import render

    for path, text in _run(render, root).items():
        typer.echo(f"<!-- {path} -->\n{text}")


@leaderboard_app.command("rescore")
def leaderboard_rescore(
    dataset: Annotated[Path, typer.Option(help="The dataset the entries were scored on.")],
    root: _ROOT = Path("leaderboards"),
    all_: Annotated[bool, typer.Option(
        "--all", help="Re-score entries of the current metric version too.")] = False,
    force: Annotated[bool, typer.Option("--force", hidden=True)] = False,
) -> None:
    """Re-score stored entries whose metric version is not the current one, then re-render."""
    from .evaluation.leaderboard import render, rescore

    changed = _run(rescore, root, dataset, force=all_ or _deprecated(force, "--force", "--all"))
    _run(render, root)
    typer.echo(f"re-scored {len(changed)} entr{'y' if len(changed) == 1 else 'ies'}")


@app.command()
def train(
    recipe: Annotated[str, _str_argument(
        help="Recipe: a registered name (flow, timesformer, resnet...; a name wins over a file "
             "of that name in the working folder) or a file: NAME.py, ./NAME.")],
    dataset: Annotated[Path, typer.Option(help="Dataset folder.")],
    split: Annotated[str, _str_option(limit=lim.MAX_SPLIT,
                                      help="Split scheme; trains on its train part.")],
    out: Annotated[Path, typer.Option(help="Output folder (checkpoints).")],
    config: Annotated[Path | None, typer.Option(
        help="JSON or TOML file overriding keys of the recipe's default config.")] = None,
    seed: Annotated[int, typer.Option(min=0, max=lim.MAX_SEED, help="Random seed.")] = 0,
    device: Annotated[str, _open_choice(
        "auto", "cpu", "cuda", callback=_text(64),
        help="auto (CUDA when present), cpu, cuda, cuda:1... At most 64 characters.")] = "auto",
    resume: Annotated[bool, typer.Option(
        "--resume/--no-resume", help="Continue from the last checkpoint in --out.")] = True,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bar.")] = False,
) -> None:
    """Train a recipe on a split's train part; prints the checkpoint path.

    Example: [bold]vtsbench train flow --dataset data/ds --split unseen_objects --out
    runs/flow[/]
    """
    import json

    from .atomic import write_text_atomic
    from .recipes import guarded, load_config, load_recipe

    rec = _run(load_recipe, recipe)
    cfg = _run(load_config, rec, config)
    existed = out.exists()
    _run(out.mkdir, parents=True, exist_ok=True)
    try:
        ckpt = _run(guarded(rec.train, f"recipe {recipe}"), dataset, split, out, cfg, seed=seed,
                    device=device, resume=resume, progress=not quiet)
    except BaseException:
        # a run that failed before its first checkpoint leaves no folder behind (one that has
        # checkpoints keeps them, so that the next train resumes)
        if not existed:
            with contextlib.suppress(OSError):
                out.rmdir()
        raise
    # the merged config, written once the run succeeded: a config.json marks a finished run
    write_text_atomic(out / "config.json", json.dumps(cfg, indent=1, sort_keys=True) + "\n")
    typer.echo(f"trained {rec.name} on {split}/train: checkpoint {ckpt}")


@app.command()
def predict(
    recipe: Annotated[str, _str_argument(
        help="Recipe: a registered name (flow, timesformer, resnet...; a name wins over a file "
             "of that name in the working folder) or a file: NAME.py, ./NAME.")],
    checkpoint: Annotated[Path, typer.Argument(help="Checkpoint written by vtsbench train.")],
    dataset: Annotated[Path, typer.Option(help="Dataset folder.")],
    split: Annotated[str, _str_option(limit=lim.MAX_SPLIT, help="Split scheme.")],
    out: Annotated[Path, typer.Option(help="Submission CSV to write (+ OUT.meta.json).")],
    part: Annotated[str, _str_option(limit=lim.MAX_SPLIT,
                                     help="Part of the split to predict.")] = "test",
    device: Annotated[str, _open_choice(
        "auto", "cpu", "cuda", callback=_text(64),
        help="auto, cpu, cuda, cuda:1... At most 64 characters.")] = "auto",
    method: Annotated[str | None, _str_option(
        help="Method name in the metadata (default: the recipe's name).")] = None,
    seed: Annotated[int, typer.Option(min=0, max=lim.MAX_SEED,
                                      help="Training seed, for the metadata.")] = 0,
) -> None:
    """Predict a split part with a trained recipe; writes a submission vtsbench eval accepts.

    Example: [bold]vtsbench predict flow runs/flow/checkpoint.safetensors --dataset
    data/ds --split unseen_objects --out flow.csv[/]
    """
    import time

    from .errors import VtsError
    from .recipes import check_checkpoint, guarded, load_recipe, write_submission

    rec = _run(load_recipe, recipe)
    if not checkpoint.exists():
        _fail(VtsError("checkpoint not found", checkpoint))
    _run(check_checkpoint, checkpoint)
    t0 = time.perf_counter()
    rows = _run(guarded(rec.predict, f"recipe {recipe}"), checkpoint, dataset, split, part,
                device=device)
    wall = time.perf_counter() - t0
    n = len({r["sample_id"] for r in rows})
    extra = {"split": split, "part": part, "checkpoint": str(checkpoint),
             "predict_seconds_per_sample": round(wall / max(n, 1), 6)}
    lat = getattr(rec, "latency_s", None)
    if lat:
        extra["latency_ms_per_sample_median"] = round(1000 * sorted(lat)[len(lat) // 2], 3)
    from .environment import environment

    extra["environment"] = environment(device)
    scale = getattr(rec, "input_scale_xy", None)  # model-input px per sensor px (x, y)
    if scale:
        extra["input_scale_xy"] = [round(float(v), 6) for v in scale]
    sub, meta = _run(write_submission, rows, out, method=method or rec.name,
                     dataset_path=dataset, recipe=str(recipe), seeds=[seed], extra=extra)
    typer.echo(f"wrote {len(rows)} rows for {n} samples to {sub} and {meta}")


# -- collect: registered below --


@app.command()
def collect(
    out: Annotated[Path, typer.Argument(help="Recordings folder to create (or add to, --append).")],
    source: Annotated[str, _str_option(limit=lim.MAX_PATH_TEXT,
                                       help="Camera index (0, 1, ...) or video file.")],
    session: Annotated[str, _str_option(help="Session id (one sitting of one sensor).")] = "s0",
    sensor: Annotated[str | None, _str_option(
        help="Sensor id (new session; default 'unknown').")] = None,
    mm_per_px: Annotated[float | None, _number_option(
        high=lim.MAX_MM_PER_PX, help="Scale, mm per pixel.")] = None,
    fps: Annotated[float | None, _number_option(
        high=lim.MAX_FPS,
        help="Frame rate (default: as the source reports it).")] = None,
    mount_rotation: Annotated[float | None, _number_option(
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
    kind: Annotated[Literal["sequence", "static", "press"], _choice(
        help="sequence, static or press.")] = "sequence",
    window: Annotated[int, typer.Option(min=2, max=lim.MAX_FRAMES,
                                        help="Frames per sequence window.")] = 8,
    stride: Annotated[int | None, typer.Option(
        min=1, max=lim.MAX_STRIDE, help="Step between windows (default: --window).")] = None,
    every: Annotated[int, typer.Option(
        min=1, max=lim.MAX_STRIDE,
        help="static: keep every K-th frame; press: at most one frame per K.")] = 10,
    ball_radius_mm: Annotated[float | None, _number_option(
        high=lim.MAX_MM,
        help="Indenter ball radius in mm (required for --kind press).")] = None,
    ball_radius: Annotated[float | None, typer.Option(
        "--ball-radius", callback=_finite, hidden=True)] = None,
    contact_level: Annotated[float, _number_option(
        low=0.0, high=255.0,
        help="press: gray levels of (blurred) change that count as contact.")] = 10.0,
    contact_area: Annotated[float, _number_option(
        high=1.0,
        help="press: fraction of pixels in contact that makes a press frame.")] = 0.001,
    object_name: Annotated[str | None, _str_option("--object", help="Object label.")] = None,
    take: Annotated[str | None, _str_option(
        help="Take name (default: next free number).")] = None,
    max_frames: Annotated[int | None, typer.Option(
        min=1, max=lim.MAX_TAKE_FRAMES,
        help="Stop after this many frames (background included).")] = None,
    motion_log: Annotated[Path | None, typer.Option(
        help="CSV with columns t_s,x_mm,y_mm,z_mm (stage motion; z into the gel).")] = None,
    log_offset: Annotated[float, _number_option(
        low=-1e6, high=1e6,
        help="Log time of frame 0 in seconds: frame i is at i / fps + offset.")] = 0.0,
    slip_threshold_mm: Annotated[float | None, _number_option(
        high=lim.MAX_MM,
        help="Lateral motion (mm) over a window that makes a slip (default 0.05).")] = None,
    press_threshold_mm: Annotated[float | None, _number_option(
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
    from .collect import CollectOptions
    from .collect import collect as run_collect

    opts = CollectOptions(
        source=source, session=session, sensor=sensor, mm_per_px=mm_per_px, fps=fps,
        mount_rotation_deg=mount_rotation, mount_mirror=mount_mirror,
        background_frames=background_frames, background=background, kind=kind, window=window,
        stride=stride, every=every,
        ball_radius_mm=ball_radius_mm if ball_radius_mm is not None
        else _deprecated(ball_radius, "--ball-radius", "--ball-radius-mm"),
        contact_level=contact_level,
        contact_area=contact_area, object=object_name, take=take, max_frames=max_frames,
        motion_log=motion_log, log_offset_s=log_offset, slip_threshold_mm=slip_threshold_mm,
        press_threshold_mm=press_threshold_mm, append=append, overwrite=overwrite)
    res = _run(run_collect, out, opts, progress=not quiet)
    if res.stopped:
        typer.echo("stopped by Ctrl-C: kept the entries completed so far", err=True)
    typer.echo(f"wrote {len(res.entries)} {kind} entries to {out} (session {res.session}, "
               f"take {res.take}; {res.frames_read} frames read)")


def main() -> None:
    """Console entry point. A bad option or argument is one line on stderr naming it (exit 2),
    like every other user error, instead of click's multi-line usage box."""
    try:  # typer >= 0.2x carries its own click, whose exceptions derive from this
        from typer import TyperException as ClickError
    except ImportError:  # pragma: no cover - older typer on the click package
        from click import ClickException as ClickError

    try:
        rv = app(prog_name="vtsbench", standalone_mode=False)
    except typer.Abort:
        print("error: aborted", file=sys.stderr)
        sys.exit(1)
    except ClickError as e:
        ctx = getattr(e, "ctx", None)
        hint = f" (see `{ctx.command_path} --help`)" if ctx is not None else ""
        if e.format_message():  # empty after a group's help was shown for no command
            from .errors import one_line

            print(f"error: {one_line(e.format_message())}{hint}", file=sys.stderr)
        sys.exit(getattr(e, "exit_code", 2))
    # a command's typer.Exit(code) comes back as its code; a command that returns is a success
    sys.exit(rv if isinstance(rv, int) else 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
