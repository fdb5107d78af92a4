"""docs/cli.md is generated from the command line and must match it."""

from pathlib import Path

from tests.fixtures.data import ROOT
from vtsbench.cli.doc import main, markdown

DOC = ROOT / "docs" / "cli.md"


def test_cli_reference_is_up_to_date() -> None:
    assert DOC.read_text(encoding="utf-8") == markdown(), (
        "docs/cli.md is out of date: run `python -m vtsbench.cli.doc docs/cli.md`")


def test_every_command_and_option_is_listed(tmp_path: Path) -> None:
    import typer

    from vtsbench.cli import app
    from vtsbench.cli.doc import commands

    out = tmp_path / "cli.md"
    assert main([str(out)]) == 0
    text = out.read_text(encoding="utf-8")
    for path, cmd in commands(typer.main.get_command(app)):
        assert f"## `{' '.join(('vtsbench', *path))}`" in text
        for p in cmd.params:
            if p.hidden:  # an old spelling kept for scripts (named in the conventions)
                continue
            assert f"`{p.opts[0]}" in text or f"`{p.name.upper()}`" in text, (path, p.name)
    assert "`[dct\\|dst\\|masked]`" in text and "## One name per idea" in text
