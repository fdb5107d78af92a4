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
