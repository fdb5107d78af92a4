"""Bounds on what a user gives: sizes, counts and strings past their bound are one line naming
the option or file (exit 2, no traceback) before any work; error lines stay one bounded line
whatever they quote; a built-in recipe name is never shadowed by a file."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from vtsbench.cli import app
from vtsbench.errors import VtsError


class Result:
    """What `vtsbench ARGS` printed (stdout and stderr) and its exit code."""

    def __init__(self, exit_code: int, output: str) -> None:
        self.exit_code, self.output = exit_code, output


def run(*args: object) -> Result:
    """`vtsbench ARGS` through the console entry point (usage errors as one line, like a user
    sees them), in this process."""
    import contextlib
    import io

    from vtsbench.cli import main

    out, argv = io.StringIO(), sys.argv
    sys.argv = ["vtsbench", *(str(a) for a in args)]
    code: object = 0
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
            main()
    except SystemExit as e:
        code = e.code
    finally:
        sys.argv = argv
    return Result(code if isinstance(code, int) else 1, out.getvalue())


def clean(res: Result, code: int, *names: object) -> str:
    """Assert a clean failure: the exit code, no traceback, one line, the names in it."""
    out = res.output
    assert res.exit_code == code, out[:2000]
    assert "Traceback" not in out
    assert len(out.strip().splitlines()) == 1, out[:2000]
    for n in names:
        assert str(n) in out, (n, out[:2000])
    return out


# -- sizes and counts: refused before any work ------------------------------------------------


@pytest.mark.parametrize("args, name", [
    (("--size", "100000x100000"), "--size"),
    (("--frames", "100000"), "--frames"),
    (("--frames", "1000"), "--frames"),  # in range alone, but 307 million pixels a sequence
    (("--static", "20000"), "--static"),
    (("--sequences", "20000"), "--sequences"),
    (("--presses", "20000"), "--presses"),
    (("--sessions", "5000"), "--sessions"),
    (("--workers", "1000"), "--workers"),
    (("--seed", str(2**40)), "--seed"),
    (("--mm-per-px", "1e6"), "--mm-per-px"),
])
def test_simulate_bounds_are_one_line_before_any_work(tmp_path: Path, args, name) -> None:
    clean(run("simulate", tmp_path / "o", *args), 2, name)
    assert not (tmp_path / "o").exists() and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("kw, name", [
    ({"size": (100000, 100000)}, "--size"), ({"frames": 100000}, "--frames"),
    ({"n_static": 10**6}, "--static"), ({"workers": 10**4}, "--workers"),
    ({"frames": 400, "size": (480, 640)}, "million pixels"),
])
def test_simulate_library_bounds(tmp_path: Path, kw, name) -> None:
    from vtsbench.sim.simulate import simulate

    with pytest.raises(VtsError, match=name):
        simulate(tmp_path / "o", **kw)
    assert not (tmp_path / "o").exists()


def test_simulate_help_states_the_bounds() -> None:
    out = CliRunner().invoke(app, ["simulate", "--help"]).output
    for bound in ("4096", "1000", "10000", "100 million", "256"):
        assert bound in out, bound


def test_build_shard_mb_out_of_range(tmp_path: Path) -> None:
    from vtsbench.dataset.build.options import BuildOptions, check_options

    clean(run("build", tmp_path, tmp_path / "o", "--shard-mb", "1e300"), 2, "--shard-mb")
    with pytest.raises(VtsError, match="--shard-mb"):
        check_options(BuildOptions(shard_mb=1e300))
    for opts in (BuildOptions(frames=10**6), BuildOptions(workers=10**4),
                 BuildOptions(seed=2**70), BuildOptions(version="1.0.0+" + "a" * 100)):
        with pytest.raises(VtsError, match="--"):
            check_options(opts)
    check_options(BuildOptions())  # the defaults stay allowed


@pytest.mark.parametrize("args, name", [
    (("preview", "{t}", "-n", "100000"), "-n"),
    (("calibrate", "{t}", "--out", "{t}/c.safetensors", "--bins", "100000"), "--bins"),
    (("calibrate", "{t}", "--out", "{t}/c.safetensors", "--seed", "-1"), "--seed"),
    (("depth", "{t}", "--calibration", "{t}/c", "--batch", "100000"), "--batch"),
    (("export-hf", "{t}", "--workers", "100000"), "--workers"),
    (("export-hf", "{t}", "--license", "x" * 300), "--license"),
    (("eval", "{t}/s.csv", "--dataset", "{t}", "--split", "s" * 300), "--split"),
    (("predict", "flow", "{t}/c", "--dataset", "{t}", "--split", "seen", "--out", "{t}/p.csv",
      "--method", "m" * 300), "--method"),
    (("collect", "{t}/o", "--source", "0", "--window", "100000"), "--window"),
    (("collect", "{t}/o", "--source", "0", "--sensor", "s" * 300), "--sensor"),
    (("collect", "{t}/o", "--source", "0", "--contact-level", "1e9"), "--contact-level"),
    (("collect", "{t}/o", "--source", "0", "--mount-rotation", "nan"), "finite"),
    (("manifest", "{t}", "--pattern", "{object}.png", "--stride", "10000000000"), "--stride"),
    (("push", "{t}", "r" * 300, "--dry-run"), "REPO_ID"),
])
def test_command_options_are_bounded(tmp_path: Path, args, name) -> None:
    res = run(*(a.replace("{t}", str(tmp_path)) for a in args))
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    assert name.lower() in res.output.lower(), res.output
    assert list(tmp_path.iterdir()) == []


def test_every_user_given_number_and_string_has_a_bound() -> None:
    """Each visible integer, number or text option and argument of every command states its
    bound in --help: a range, 'At most N', 'From A to B' (paths are the file system's, a
    choice is its values)."""
    import typing

    import typer

    from vtsbench.cli.doc import _literal, commands

    unbounded = []
    for path, cmd in commands(typer.main.get_command(app)):
        for p in cmd.params:
            ann = getattr(getattr(p, "type_descriptor", None), "annotation", str)
            if p.hidden or getattr(p, "is_flag", False) or _literal(ann):
                continue
            args = [a for a in typing.get_args(ann) if a is not type(None)] or [ann]
            base = typing.get_args(args[0])[0] if typing.get_origin(args[0]) is list else args[0]
            name = getattr(base, "__name__", "")
            if name in ("int", "float"):
                ok = (p.min is not None or p.max is not None
                      or any(w in (p.help or "") for w in (" At most ", " From ")))
            elif name == "str":
                ok = "At most" in (p.help or "") or (name == "str" and p.name == "size"
                                                     and "4096" in (p.help or ""))
            else:
                ok = name in ("Path", "bool")
            if not ok:
                unbounded.append(f"{' '.join(path)} {p.name} ({name})")
    assert not unbounded, unbounded


# -- checkpoints and recipes -------------------------------------------------------------------


def test_predict_with_a_csv_as_checkpoint(built: Path, tmp_path: Path) -> None:
    csv = tmp_path / "some.csv"
    csv.write_text("a,b\n1,2\n")
    clean(run("predict", "flow", csv, "--dataset", built, "--split", "seen", "--out",
              tmp_path / "p.csv"), 2, "some.csv", "not a flow recipe checkpoint")
    assert not (tmp_path / "p.csv").exists()


@pytest.mark.parametrize("missing", ["torch", "transformers"])
def test_train_timesformer_without_torch_is_one_line(built: Path, tmp_path: Path,
                                                     missing: str) -> None:
    code = (f"import sys; sys.modules[{missing!r}] = None; from vtsbench.cli import main; "
            "sys.argv = ['vtsbench', 'train', 'timesformer', '--dataset', sys.argv[1], "
            "'--split', 'seen', '--out', sys.argv[2]]; main()")
    res = subprocess.run([sys.executable, "-c", code, str(built), str(tmp_path / "r")],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr[-3000:]
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and missing in lines[0] and "vtsbench[torch]" in lines[0], lines
    assert not (tmp_path / "r").exists()


def test_a_file_named_like_a_builtin_recipe_does_not_shadow_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from vtsbench.recipes import load_recipe

    monkeypatch.chdir(tmp_path)
    (tmp_path / "flow").write_text("raise SystemExit('the file, not the built-in recipe')\n")
    assert load_recipe("flow").name == "flow"
    with pytest.raises(SystemExit, match="the file"):  # an explicit path means the file
        load_recipe("./flow")
    (tmp_path / "flow").write_text("from vtsbench.recipes_builtin.flow import RECIPE\n")
    (tmp_path / "mine").write_text("from vtsbench.recipes_builtin.flow import RECIPE\n")
    assert load_recipe("./flow").name == "flow"
    assert load_recipe("mine").name == "flow"  # a bare name no recipe has: still a file


# -- error lines: one line, bounded ------------------------------------------------------------


def test_vts_error_is_one_bounded_line() -> None:
    err = VtsError(f"wrong dataset version {'1' * 200_000!r}", "p.json")
    text = str(err)
    assert len(text) < 1200 and "200" in text and "characters)" in text
    err = VtsError("no sample 'a\nb\rc\x1b[31m\u2028d'", "dir\nname/x.json")
    assert "\n" not in str(err) and "\r" not in str(err) and "\x1b" not in str(err)
    assert "\u2028" not in str(err) and "a\\nb" in str(err) and "dir\\nname" in str(err)
    assert err.path == "dir\nname/x.json" and err.reason.startswith("no sample")


def test_cli_error_with_a_newline_in_a_path_is_one_line(tmp_path: Path) -> None:
    ckpt = tmp_path / "a\nb.safetensors"
    clean(run("predict", "flow", ckpt, "--dataset", tmp_path, "--split", "seen", "--out",
              tmp_path / "p.csv"), 2, "a\\nb.safetensors", "not found")


def test_click_usage_error_quoting_a_huge_value_is_bounded() -> None:
    code = ("import sys; from vtsbench.cli import main; sys.argv = ['vtsbench', 'simulate', "
            "'o', '--static', 'x\\n' * 50000]; main()")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60)
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1, res.stderr[:500]
    assert len(res.stderr) < 2000 and "--static" in res.stderr


# -- submission metadata: bounded strings, no entry written --------------------------------------


def _submission(ds: Path, folder: Path, **meta: object) -> Path:
    """A complete, correct submission of seen/test with META in its metadata file."""
    from vtsbench.dataset.format.info import load_info
    from vtsbench.evaluation.submission import load_truth

    t = load_truth(ds, "seen", "test")
    info = load_info(ds)
    folder.mkdir(parents=True, exist_ok=True)
    sub = folder / "s.csv"
    sub.write_text("sample_id,task,pred\n" + "".join(
        f"{s},state,{int(v)}\n" for s, v in zip(t.ids, t.labels["state"], strict=True)))
    doc = {"method": "toy", "dataset_version": info.dataset_version,
           "dataset_sha256": info.dataset_sha256, **meta}
    (folder / "s.meta.json").write_text(json.dumps(doc))
    return sub


def test_a_5_mb_method_name_is_refused_and_no_entry_written(built: Path, tmp_path: Path
                                                           ) -> None:
    sub = _submission(built, tmp_path / "sub", method="m" * 5_000_000)
    out = clean(run("eval", sub, "--dataset", built, "--split", "seen"), 2, "s.meta.json")
    assert len(out) < 2000
    root = tmp_path / "lb"
    out = clean(run("leaderboard", "add", sub, "--dataset", built, "--split", "seen", "--root",
                    root), 2, "s.meta.json")
    assert len(out) < 2000 and not list(root.rglob("*.json"))


@pytest.mark.parametrize("meta, shown", [
    ({"method": "m" * 10_000}, "method"),
    ({"dataset_version": "1" * 30_000}, "dataset_version"),
    ({"url": "u" * 5000}, "url"),
    ({"method": "two\nlines"}, "method"),
])
def test_over_long_or_multiline_metadata_is_one_bounded_line(built: Path, tmp_path: Path,
                                                             meta, shown) -> None:
    sub = _submission(built, tmp_path / "sub", **meta)
    out = clean(run("eval", sub, "--dataset", built, "--split", "seen"), 2, "s.meta.json",
                shown)
    assert len(out) < 2500
    root = tmp_path / "lb"
    clean(run("leaderboard", "add", sub, "--dataset", built, "--split", "seen", "--root", root),
          2, "s.meta.json")
    assert not list(root.rglob("*.json"))


def test_metadata_within_the_bounds_is_scored(built: Path, tmp_path: Path) -> None:
    sub = _submission(built, tmp_path / "sub", method="m" * 200, notes="n\n" * 1000)
    res = run("eval", sub, "--dataset", built, "--split", "seen")
    assert res.exit_code == 0, res.output
