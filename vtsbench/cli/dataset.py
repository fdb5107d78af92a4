"""The build stage's commands: benchmark, build, info, verify, export-hf and push. Each parses its
options, calls the library (imported inside it) and prints the result."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import typer

from .. import limits as lim
from .options import choice, deprecated, number_option, str_argument, str_option
from .run import console, report_problems, run


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
    from ..sim.benchmark import make_benchmark

    made = run(make_benchmark, name, out, seed=seed, workers=workers, overwrite=overwrite,
               progress=not quiet, log=lambda m: typer.echo(m, err=m.startswith("warning")))
    print_build(made["build"])
    s = made["seconds"]
    typer.echo(f"benchmark {name} (seed {made['config']['seed']}, dataset version "
               f"{made['config']['dataset_version']}) in {out}: simulate {s['simulate']:.0f} s, "
               f"calibrate {s['calibrate']:.0f} s, build {s['build']:.0f} s")


def build(
    recordings: Annotated[Path, typer.Argument(help="Recordings folder (with recordings.json).")],
    out: Annotated[Path, typer.Argument(help="Dataset folder to create.")],
    calibration: Annotated[Path | None, typer.Option(
        help="Calibration file (default: RECORDINGS/calibration.safetensors, as written by "
             "`vtsbench calibrate RECORDINGS --out RECORDINGS/calibration.safetensors`).")
    ] = None,
    solver: Annotated[Literal["dct", "dst", "masked"], choice(
        help="Depth solver: dct, dst or masked.")] = "dct",
    no_depth: Annotated[bool, typer.Option(
        "--no-depth", help="RGB only: no depth or contact arrays, no calibration needed (for "
                           "sensors without calibration presses).")] = False,
    frames: Annotated[int, typer.Option(min=1, max=lim.MAX_FRAMES,
                                        help="Frames per slip sample (T).")] = 8,
    workers: Annotated[int, typer.Option(
        min=1, max=lim.MAX_WORKERS,
        help="Worker processes (or Dask workers with --scheduler local).")] = 1,
    scheduler: Annotated[str | None, str_option(
        limit=lim.MAX_PATH_TEXT,
        help="Dask scheduler address (tcp://host:8786), or 'local' for a LocalCluster of "
             "--workers processes. OUT must be on a file system the workers share.")] = None,
    skip_bad: Annotated[bool, typer.Option(
        "--skip-bad", help="Leave bad recordings out (listed in meta/build_report.json) instead of "
             "stopping.")] = False,
    overwrite: Annotated[bool, typer.Option(
        "--overwrite", help="Replace OUT if it exists.")] = False,
    dataset_version: Annotated[str, str_option(
        limit=lim.MAX_VERSION,
        help="The dataset's version (semantic version of its content; `vtsbench --version` is "
             "the program's).")] = "1.0.0",
    version: Annotated[str | None, typer.Option("--version", hidden=True)] = None,
    compression_level: Annotated[int, typer.Option(
        min=0, max=22, help="zstd level of the arrays; 0 stores them uncompressed.")] = 3,
    seed: Annotated[int, typer.Option(min=0, max=lim.MAX_SEED,
                                      help="Seed of the split files.")] = 0,
    shard_mb: Annotated[float, number_option(
        low=lim.MIN_SHARD_MB, high=lim.MAX_SHARD_MB,
        help="Target uncompressed RGB shard size in MB (whole samples per shard).")] = 32.0,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bars.")] = False,
    holdout_objects: Annotated[Path | None, typer.Option(
        help="File of object names, one a line: adds the split scheme given_objects, test = "
             "exactly these objects, val = other whole objects.")] = None,
    split_file: Annotated[list[Path] | None, typer.Option(
        help="A split scheme of your own (JSON in schemas/split.schema.json); repeatable.")
    ] = None,
    store: Annotated[Literal["samples", "episodes"], choice(
        help="samples: every sample's frames in arrays of their own; episodes: each take "
             "stored once, the samples views of it (format 1.3).")] = "samples",
    video: Annotated[Literal["ffv1", "h264", "av1"] | None, choice(
        help="With --store episodes: each take's RGB as one video file, ffv1 (lossless), h264 "
             "(crf 18) or av1 (crf 30); depth and contact stay in Zarr. Default: RGB in Zarr.")
    ] = None,
) -> None:
    """Build an RGB-D dataset (Zarr + parquet index + splits + card) from a recordings folder
    (RGB only with --no-depth).

    Atomic and resumable: writes into .OUT.partial beside OUT; rerun the same command after an
    interruption and finished shards are kept. Example:
    [bold]vtsbench build data/rec data/ds --workers 2[/]
    """
    from rich.console import Console

    from ..dataset.build import BuildOptions
    from ..dataset.build import build as run_build

    err_console = Console(stderr=True, highlight=False)
    opts = BuildOptions(calibration=calibration, solver=solver, depth=not no_depth,
                        frames=frames, workers=workers,
                        scheduler=scheduler, skip_bad=skip_bad, overwrite=overwrite,
                        version=deprecated(version, "build --version", "--dataset-version")
                        or dataset_version, compression_level=compression_level, seed=seed,
                        shard_mb=shard_mb, progress=not quiet,
                        holdout_objects=holdout_objects, split_files=tuple(split_file or ()),
                        store=store, video=video)
    res = run(run_build, recordings, out, opts,
              log=lambda m: err_console.print(m, soft_wrap=True, markup=False))
    print_build(res)


def print_build(res) -> None:
    """The skipped entries and a summary table of a build."""
    from rich.markup import escape
    from rich.table import Table

    from ..dataset.tools.info import human

    con = console()
    for w in res.warnings:
        con.print(f"[yellow]warning[/] {escape(w)}", soft_wrap=True)
    for eid, why in res.skipped.items():
        con.print(f"[yellow]skipped[/] {escape(f'{eid}: {why}')}", soft_wrap=True)
    for why in res.splits_skipped.values():
        con.print(f"[yellow]split not made[/] {escape(why)}", soft_wrap=True)
    t = Table(title=escape(f"built {res.out}"), title_justify="left")
    for c in ("kind", "samples", "frames", "shards"):
        t.add_column(c, justify="left" if c == "kind" else "right")
    for kind in ("static", "slip"):
        t.add_row(kind, str(res.samples[kind]), str(res.frames[kind]), str(res.shards[kind]))
    con.print(t)
    frames, size = sum(res.frames.values()), human(sum(res.bytes_on_disk.values()))
    made = ("shards" if res.takes is None else "takes") + f" built {res.shards_built}"
    con.print(f"{frames} frames in {res.seconds:.1f} s ({frames / max(res.seconds, 1e-9):.0f}"
              f" frames/s); {made}, kept from a partial build "
              f"{res.shards_kept}; {len(res.skipped)} entries skipped; splits: "
              f"{', '.join(res.splits) or 'none'}; {size} on disk")


def info(
    dataset: Annotated[str, str_argument(
        help="Dataset folder (made by vtsbench build), or a URL as vtsbench.load takes "
             "(file://, http(s)://, s3://...).")],
) -> None:
    """Summarise a dataset: samples per object, state, direction and split part; sizes on disk;
    versions and checksum."""

    from ..dataset.tools.info import render, summarise

    render(run(summarise, dataset), console())


def verify(
    dataset: Annotated[str, str_argument(
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

    from ..dataset.tools.verify import verify as run_verify

    report = run(run_verify, dataset, decode=not quick, progress=True)
    report_problems(report.problems, report.warnings,
                    f"{report.files} files, {report.samples} samples, {report.shards} shards "
                    f"checked: {len(report.problems)} problem(s)")


def export_hf(
    dataset: Annotated[Path, typer.Argument(help="Dataset folder (made by vtsbench build).")],
    workers: Annotated[int, typer.Option(min=1, max=lim.MAX_WORKERS,
                                         help="Threads encoding the PNGs.")] = 1,
    license: Annotated[str, str_option(
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

    from ..dataset.tools.hub import export_hf as run_export

    res = run(run_export, dataset, workers=workers, license=license, progress=not quiet)
    console().print(res.summary())


def push(
    dataset: Annotated[Path, typer.Argument(help="Dataset folder (made by vtsbench build).")],
    repo_id: Annotated[str, str_argument(limit=lim.MAX_NAME,
                                         help="Hub dataset repository, e.g. my-lab/tactile.")],
    dry_run: Annotated[bool, typer.Option(
        "--dry-run", help="List what would be uploaded and stop (no network).")] = False,
    zarr: Annotated[bool, typer.Option(
        help="Upload the Zarr arrays (data/) too, so vtsbench.load reads the repository; "
             "--no-zarr uploads the parquet copy, index, splits and card only.")] = True,
    private: Annotated[bool, typer.Option(
        "--private", help="Create the repository private.")] = False,
    revision: Annotated[str | None, str_option(help="Branch to push to.")] = None,
) -> None:
    """Upload a verified dataset to the Hugging Face Hub (run `vtsbench export-hf` first for
    the viewer and `datasets.load_dataset`). Example:
    [bold]vtsbench push data/ds my-lab/tactile --dry-run[/]
    """

    from ..dataset.tools.push import push as run_push
    from ..dataset.tools.push import push_plan

    con = console()
    plan = run(push_plan, dataset, zarr, repo_id)
    if not plan.has_hub_copy:
        con.print(f"[yellow]warning[/] {plan.NO_HUB_COPY}", soft_wrap=True)
    if dry_run:
        *files, total = plan.listing(repo_id)
        for line in files:
            con.print(line, soft_wrap=True)
        con.print(total)
        return
    con.print(plan.uploaded(run(run_push, dataset, repo_id, zarr=zarr, private=private,
                                revision=revision)))
