"""The command line starts light and answers help for every command."""

import subprocess
import sys

import pytest
from typer.testing import CliRunner

from vtsbench.cli import app

HEAVY = ("numpy", "cv2", "scipy", "matplotlib", "torch", "transformers", "jsonschema")


def test_start_up_imports_nothing_heavy() -> None:
    code = ("import sys, vtsbench.cli; "
            f"print(','.join(m for m in {HEAVY!r} if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_help_runs_without_heavy_imports() -> None:
    code = ("import sys\nfrom vtsbench.cli import app\n"
            "try:\n    app(['--help'], prog_name='vtsbench')\nexcept SystemExit:\n    pass\n"
            f"print('HEAVY=' + ','.join(m for m in {HEAVY!r} if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "HEAVY=\n" in out.stdout + "\n" and "simulate" in out.stdout


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
    assert "[dct|dst|masked]" in res.output
    res = CliRunner().invoke(app, ["calibrate", "-h"], env={"COLUMNS": "200"})
    assert "[lut|poly|mlp]" in res.output and "[label|detect]" in res.output
    env = {"_VTSBENCH_COMPLETE": "complete_bash", "COMP_WORDS": "vtsbench calibrate r --method p",
           "COMP_CWORD": "4", "PATH": ""}
    out = subprocess.run([sys.executable, "-m", "vtsbench"], env=env, capture_output=True,
                         text=True)
    assert out.stdout.split() == ["poly"], out.stderr


def test_completion_script() -> None:
    res = CliRunner().invoke(app, ["--show-completion", "bash"])
    assert res.exit_code == 0 and "_VTSBENCH_COMPLETE" in res.output
