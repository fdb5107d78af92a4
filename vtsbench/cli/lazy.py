"""Commands built when they are looked up, not at every start.

Typer turns each command's signature into click parameters when the command line is put
together: about 11 ms a command on a 2-core Xeon (typing's get_type_hints and inspect's
signatures), 0.25 s for all 22, paid by every `vtsbench` call, `--help` included. `LazyTyper`
registers commands as typer does, but its click group (`LazyGroup`) builds a command only when
it is looked up (`get_command`: to run it, complete it or show its help); the group's own help
lists the commands from their docstrings alone (`summary`), without building them."""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterator, Mapping, MutableMapping
from typing import Any

import typer
from typer.core import TyperCommand, TyperGroup
from typer.models import CommandInfo, DefaultPlaceholder


class LazyCommands(MutableMapping[str, Any]):
    """A group's commands by name, in registration order: a registered command is built
    (`LazyTyper.build`) when first read; `built` says whether it has been."""

    def __init__(self, source: LazyTyper, given: Mapping[str, Any]) -> None:
        self.source, self._built = source, dict(given)

    def built(self, name: str) -> bool:
        return name in self._built

    def __getitem__(self, name: str) -> Any:
        if name not in self._built:
            if name not in self.source.lazy:
                raise KeyError(name)
            self._built[name] = self.source.build(name)
        return self._built[name]

    def __setitem__(self, name: str, cmd: Any) -> None:
        self._built[name] = cmd

    def __delitem__(self, name: str) -> None:
        del self._built[name]

    def __iter__(self) -> Iterator[str]:
        yield from self.source.lazy
        yield from (n for n in self._built if n not in self.source.lazy)

    def __len__(self) -> int:
        return len(self.source.lazy) + sum(n not in self.source.lazy for n in self._built)


class LazyGroup(TyperGroup):
    """A typer group whose commands (`LazyCommands`) come from its `LazyTyper` (`source`) and
    are built on first lookup; while its help is rendered, unbuilt commands are given as
    summaries."""

    source: LazyTyper  # set on the subclass `LazyTyper` makes for each app

    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self.commands = LazyCommands(self.source, self.commands)
        self._listing = False

    def list_commands(self, ctx: Any) -> list[str]:
        return list(self.commands)  # the names alone (typer's reads every command)

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        if self._listing and cmd_name in self.source.lazy and not self.commands.built(cmd_name):
            return self.source.summary(cmd_name, self.rich_markup_mode)
        return super().get_command(ctx, cmd_name)

    def format_help(self, ctx: Any, formatter: Any) -> None:
        self._listing = True  # the command list needs names and help texts only
        try:
            super().format_help(ctx, formatter)
        finally:
            self._listing = False


class LazyTyper(typer.Typer):
    """A typer app whose commands (`lazy_command`) and sub-apps (`lazy_typer`) are built into
    click commands one at a time, when looked up (see the module doc)."""

    def __init__(self, **kw: Any) -> None:
        super().__init__(cls=type("LazyGroup", (LazyGroup,), {"source": self}), **kw)
        self.lazy: dict[str, CommandInfo | typer.Typer] = {}

    def lazy_command(self, name: str, callback: Callable[..., Any]) -> None:
        """Register `callback` as the command `name` (listed in registration order)."""
        self.lazy[name] = CommandInfo(name=name, callback=callback)

    def lazy_typer(self, name: str, app: typer.Typer) -> None:
        """Register `app` as the command group `name`."""
        self.lazy[name] = app

    def build(self, name: str) -> Any:
        """The click command or group of `name`, with its parameters."""
        entry = self.lazy[name]
        if isinstance(entry, typer.Typer):
            group = typer.main.get_group(entry)
            group.name = name
            return group
        return typer.main.get_command_from_info(
            entry, pretty_exceptions_short=self.pretty_exceptions_short,
            rich_markup_mode=self.rich_markup_mode)

    def summary(self, name: str, markup_mode: Any) -> Any:
        """A parameterless stand-in for `name` in its group's command list: its help text."""
        entry = self.lazy[name]
        if isinstance(entry, typer.Typer):
            text = entry.info.help
            return TyperGroup(name=name, help=None if isinstance(text, DefaultPlaceholder)
                              else text, rich_markup_mode=markup_mode)
        return TyperCommand(name=name, help=inspect.getdoc(entry.callback),
                            rich_markup_mode=markup_mode)
