"""The command line starts light and answers help for every command."""

import os
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from vtsbench.cli import app

HEAVY = ("numpy", "cv2", "scipy", "matplotlib", "torch", "transformers", "jsonschema")


def test_start_up_imports_nothing_heavy() -> None:
    code = ("import sys, vtsbench.cli; "
            f"print(','.join(m for m in {HEAVY!r} if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_start_up_leaves_the_help_renderer_until_help_is_shown() -> None:
    """typer's rich_utils (rich's markdown and columns, about 0.3 s) is imported when help is
    rendered, not when the command line is built; rendered, it folds a long word rather than
    cutting it."""
    code = ("import sys\nfrom vtsbench.cli import app\n"
            "print('BEFORE', 'typer.rich_utils' in sys.modules)\n"
            "try:\n    app(['build', '--help'], prog_name='vtsbench')\nexcept SystemExit:\n"
            "    pass\nprint('AFTER', 'typer.rich_utils' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env={**os.environ, "COLUMNS": "50"})
    assert "BEFORE False" in out.stdout and "AFTER True" in out.stdout
    assert "…" not in out.stdout  # the fold is installed before the first help


def test_help_leaves_what_it_does_not_use_to_a_later_import() -> None:
    """rich's markdown and traceback, which typer's rich_utils imports and our help never uses,
    are not imported by --help; rich_utils's names for them still give the real classes."""
    code = ("import sys\nfrom vtsbench.cli import app\n"
            "try:\n    app(['--help'], prog_name='vtsbench')\nexcept SystemExit:\n    pass\n"
            "print('LOADED', 'rich.markdown' in sys.modules, 'rich.traceback' in sys.modules)\n"
            "from typer import rich_utils\nimport rich.markdown, rich.traceback\n"
            "md = rich_utils._make_rich_text(text='**b**', markup_mode='markdown')\n"
            "try:\n    1 / 0\nexcept ZeroDivisionError as e:\n"
            "    tb = rich_utils.Traceback.from_exception(type(e), e, e.__traceback__)\n"
            "print('REAL', isinstance(md, rich.markdown.Markdown), "
            "isinstance(tb, rich.traceback.Traceback))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "LOADED False False" in out.stdout and "REAL True True" in out.stdout, out.stdout


def test_help_runs_without_heavy_imports() -> None:
    code = ("import sys\nfrom vtsbench.cli import app\n"
            "try:\n    app(['--help'], prog_name='vtsbench')\nexcept SystemExit:\n    pass\n"
            f"print('HEAVY=' + ','.join(m for m in {HEAVY!r} if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "HEAVY=\n" in out.stdout + "\n" and "simulate" in out.stdout


def test_only_the_called_command_is_built(monkeypatch: pytest.MonkeyPatch) -> None:
    """Building a command's parameters costs about 11 ms: the root's help lists every command
    without building one, a command's help or run builds that command alone, and a typo is
    still answered with the close names."""
    from vtsbench.cli.lazy import LazyTyper

    built: list[str] = []
    build = LazyTyper.build
    monkeypatch.setattr(LazyTyper, "build", lambda self, name: built.append(name) or
                        build(self, name))
    res = CliRunner().invoke(app, ["--help"], env={"COLUMNS": "200"})
    assert res.exit_code == 0 and built == []
    assert all(f" {name} " in res.output for name in ("simulate", "build", "collect",
                                                      "leaderboard"))
    assert res.output.index(" collect ") < res.output.index(" leaderboard ")  # typer's order
    res = CliRunner().invoke(app, ["leaderboard", "add", "--help"])
    assert res.exit_code == 0 and "--dataset" in res.output and built == ["leaderboard", "add"]
    res = CliRunner().invoke(app, ["buld"])
    assert res.exit_code == 2 and "Did you mean 'build'" in res.output


@pytest.mark.parametrize("cmd", ["simulate", "check", "manifest", "preview", "collect", "calibrate",
                                 "depth", "build", "info", "verify"])
def test_each_command_has_help(cmd: str) -> None:
    res = CliRunner().invoke(app, [cmd, "--help"])
    assert res.exit_code == 0 and "Usage" in res.output


def _commands(cmd, path=()):
    """Every (path, click command) of the app, groups included."""
    yield path, cmd
    for name, sub in sorted(getattr(cmd, "commands", {}).items()):
        yield from _commands(sub, (*path, name))


def test_version() -> None:
    from importlib.metadata import version

    res = CliRunner().invoke(app, ["--version"])
    assert res.exit_code == 0 and res.stdout.strip() == f"vtsbench {version('vtsbench')}"


def test_short_help_everywhere_and_flags_without_no_form() -> None:
    import typer

    root = typer.main.get_command(app)
    paths = [p for p, _ in _commands(root)]
    assert ("build",) in paths and ("leaderboard", "add") in paths
    for path in paths:
        res = CliRunner().invoke(app, [*path, "-h"], env={"COLUMNS": "200"})
        assert res.exit_code == 0 and "Usage" in res.output, path
        for flag in ("quiet", "overwrite", "force", "replace", "append", "deep", "quick"):
            assert f"--no-{flag}" not in res.output, (path, flag)


def test_choices_listed_in_help_and_completed() -> None:
    res = CliRunner().invoke(app, ["build", "-h"], env={"COLUMNS": "200"})
    assert "dct|dst|masked" in res.output
    res = CliRunner().invoke(app, ["calibrate", "-h"], env={"COLUMNS": "200"})
    assert "lut|poly|mlp" in res.output and "label|detect" in res.output
    env = {"_VTSBENCH_COMPLETE": "complete_bash", "COMP_WORDS": "vtsbench calibrate r --method p",
           "COMP_CWORD": "4", "PATH": ""}
    out = subprocess.run([sys.executable, "-m", "vtsbench"], env=env, capture_output=True,
                         text=True)
    assert out.stdout.split() == ["poly"], out.stderr


def test_completion_script(monkeypatch: pytest.MonkeyPatch) -> None:
    # typer detects the user's shell (shellingham); a run with no parent shell (CI) finds none
    import typer.completion

    monkeypatch.setattr(typer.completion, "_get_shell_name", lambda: "bash")
    res = CliRunner().invoke(app, ["--show-completion", "bash"])
    assert res.exit_code == 0 and "_VTSBENCH_COMPLETE" in res.output


@pytest.mark.parametrize("args, option", [
    (["build", "rec", "ds", "--solver", "fft"], "--solver"),
    (["calibrate", "rec", "--out", "c.st", "--method", "kriging"], "--method"),
    (["calibrate", "rec", "--out", "c.st", "--solver", "fft"], "--solver"),
    (["calibrate", "rec", "--out", "c.st", "--device", "tpu"], "--device"),
    (["calibrate", "rec", "--out", "c.st", "--circles", "guess"], "--circles"),
    (["depth", "x.png", "--calibration", "c.st", "--device", "gpu"], "--device"),
    (["manifest", "f", "--pattern", "{object}.png", "--kind", "video"], "--kind"),
    (["collect", "rec", "--source", "0", "--kind", "video"], "--kind"),
])
def test_a_bad_choice_is_one_usage_line(args: list[str], option: str, tmp_path: Path,
                                        monkeypatch: pytest.MonkeyPatch,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    """Choices are checked by the command line itself: one line naming the option and the
    accepted values, exit 2, before the command runs (nothing written)."""
    from vtsbench.cli import main

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["vtsbench", *args])
    with pytest.raises(SystemExit) as e:
        main()
    err = capsys.readouterr().err.strip()
    assert e.value.code == 2 and len(err.splitlines()) == 1, err
    assert option in err and "is not one of" in err
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("args, old, new", [
    (["manifest", "f", "--pattern", "{object}.png", "--force"], "--force", "--overwrite"),
    (["build", "rec", "ds", "--version", "2.0.0"], "build --version", "--dataset-version"),
    (["collect", "rec", "--source", "missing.mp4", "--ball-radius", "2"], "--ball-radius",
     "--ball-radius-mm"),
])
def test_old_spellings_work_with_a_note(args: list[str], old: str, new: str, tmp_path: Path,
                                        monkeypatch: pytest.MonkeyPatch,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    """A renamed option's old spelling is hidden from --help but still accepted, with a
    one-line deprecation note naming the new one."""
    from vtsbench.cli import main

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["vtsbench", *args])
    with pytest.raises(SystemExit):
        main()
    err = capsys.readouterr().err
    assert f"note: {old} is deprecated; use {new}" in err
    name = args[0]
    res = CliRunner().invoke(app, [name, "-h"], env={"COLUMNS": "200"})
    assert f"{old.split()[-1]} " not in res.output.replace(new, "")


def test_stdout_console_is_wide_in_a_pipe_and_follows_columns(monkeypatch) -> None:
    """Tables printed to a pipe or log get 160 columns (rich would assume 80 and cut names);
    COLUMNS, when set, decides."""
    from vtsbench.cli.run import console as _console

    monkeypatch.delenv("COLUMNS", raising=False)
    assert _console().width == 160  # pytest's stdout is not a terminal
    monkeypatch.setenv("COLUMNS", "90")
    assert _console().width == 90
