"""Help pages in the plain style of git/pip-era tools, readable at 80 columns.

typer's rich help draws every option in a six-column box (long name, short name, negative name, type, help) that
leaves the description about 18 columns on an 80-column terminal, cuts words with an ellipsis and shows a ``<bool>``
placeholder on flags that take no value. Here instead:

* one option per row, the description wrapped beside it (or below a long name), never cut;
* flags show no placeholder (``--json``), options that take a value one UPPERCASE word (``--angles N``,
  ``--data PATH``, or the option's own ``metavar``);
* defaults one way: ``[default: X]`` (``show_default="..."`` on an option whose value comes from elsewhere, e.g. the
  rig file or the training configuration);
* options grouped under headings (``rich_help_panel``), commands grouped by what they are for
  (:data:`unitac_rig.cli.app.COMMAND_GROUPS`), each with its first sentence.

Only public typer classes are subclassed (``typer.core.TyperCommand`` / ``TyperGroup``); the app sets
``rich_markup_mode=None`` so they render through the plain formatter.
"""

from __future__ import annotations

import inspect
from collections.abc import Iterable, Mapping
from typing import Any

import typer
from typer.core import TyperArgument, TyperCommand, TyperGroup, TyperOption
from typer.models import DefaultPlaceholder

OPTIONS_HEADING = "Options"
OTHER_COMMANDS = "Other commands"


def placeholder(param: Any) -> str:
    """The one-word placeholder of an option or argument that takes a value: its metavar, else from its type."""
    if param.metavar:
        return str(param.metavar)
    if isinstance(param, TyperArgument):
        return str(param.name).upper()
    bare = str(param.bare_type()).lower()
    element = bare.removeprefix("list[").removesuffix("]")
    if param.type_descriptor.is_path or element == "path":
        return "PATH"
    return {"int": "N", "float": "NUM", "bool": "BOOL"}.get(element, "TEXT")


def _default_text(param: TyperOption) -> str | None:
    """``X`` of ``[default: X]``, or None when there is nothing worth showing."""
    if isinstance(param.show_default, str):
        return param.show_default
    default = param.default
    if param.is_flag:
        if param.secondary_opts and default is not None:  # --live/--no-live: name the one that applies
            return param.opts[0] if default else param.secondary_opts[0]
        return None  # a plain flag is off unless given
    if default is None or param.show_default is False or callable(default):
        return None
    if isinstance(default, (list, tuple)):
        return ", ".join(str(d) for d in default) or None
    return str(default)


def _range_text(param: Any) -> str | None:
    """``at least 1``, ``at most 5``, ``0 to 15``: an option's allowed range in words."""
    low, high = getattr(param, "min", None), getattr(param, "max", None)
    if low is not None and high is not None:
        return f"{low} to {high}"
    if low is not None:
        return f"at least {low}"
    if high is not None:
        return f"at most {high}"
    return None


def help_record(param: Any, ctx: Any) -> tuple[str, str] | None:
    """(the option as typed, its description with [default: ...] / [required] / range) for one parameter."""
    if getattr(param, "hidden", False):
        return None
    if isinstance(param, TyperArgument):
        name = placeholder(param) + ("..." if param.nargs != 1 else "")
        return name, (param.help or "") + ("" if param.required else "  [optional]")
    names = ", ".join(param.opts)
    if param.secondary_opts:
        names += " / " + ", ".join(param.secondary_opts)
    if not param.is_flag and not getattr(param, "count", False):
        names += " " + placeholder(param)
    extra = []
    default = _default_text(param)
    if default is not None and not param.required:
        extra.append(f"default: {default}")
    range_text = _range_text(param)
    if range_text:
        extra.append(range_text)
    if param.required:
        extra.append("required")
    text = inspect.cleandoc(param.help or "")
    if extra:
        text = f"{text}  [{'; '.join(extra)}]" if text else f"[{'; '.join(extra)}]"
    return names, text


def write_params(params: Iterable[Any], ctx: Any, formatter: Any) -> None:
    """Arguments first, then options in their groups, in the order the groups first appear."""
    arguments: list[tuple[str, str]] = []
    groups: dict[str, list[tuple[str, str]]] = {}
    for param in params:
        record = help_record(param, ctx)
        if record is None:
            continue
        if isinstance(param, TyperArgument):
            arguments.append(record)
        else:
            panel = getattr(param, "rich_help_panel", None) or OPTIONS_HEADING
            groups.setdefault(panel, []).append(record)
    if OPTIONS_HEADING in groups:  # the general options first, then the named groups
        groups = {OPTIONS_HEADING: groups.pop(OPTIONS_HEADING), **groups}
    if arguments:
        with formatter.section("Arguments"):
            formatter.write_dl(arguments)
    for heading, rows in groups.items():
        with formatter.section(heading):
            formatter.write_dl(rows)


def first_sentence(text: str | None) -> str:
    """The first sentence (or clause before a semicolon) of a command's help, for the command list."""
    paragraph = " ".join(inspect.cleandoc(text or "").split("\n\n")[0].split())
    for stop in (". ", "; "):
        head, found, _ = paragraph.partition(stop)
        if found:
            paragraph = head
    return paragraph.rstrip(".")


def usage_pieces(command: Any, ctx: Any) -> list[str]:
    """``[OPTIONS] RUN INPUT``: the arguments by their placeholders (typer wrote ``{run}``)."""
    pieces = [command.options_metavar] if command.options_metavar else []
    for param in command.get_params(ctx):
        if isinstance(param, TyperArgument):
            name = placeholder(param) + ("..." if param.nargs != 1 else "")
            pieces.append(name if param.required else f"[{name}]")
    return pieces


class PlainCommand(TyperCommand):
    """A command whose help is plain text: grouped options, one placeholder and default style, no cut words."""

    def collect_usage_pieces(self, ctx: Any) -> list[str]:
        return usage_pieces(self, ctx)

    def format_options(self, ctx: Any, formatter: Any) -> None:
        write_params(self.get_params(ctx), ctx, formatter)


class PlainGroup(TyperGroup):
    """A command group whose help lists its options, then its commands under the headings of ``command_groups``."""

    command_groups: Mapping[str, tuple[str, ...]] = {}

    def format_options(self, ctx: Any, formatter: Any) -> None:
        write_params(self.get_params(ctx), ctx, formatter)
        self.format_commands(ctx, formatter)

    def format_commands(self, ctx: Any, formatter: Any) -> None:
        listed = {name: cmd for name in self.list_commands(ctx) if (cmd := self.get_command(ctx, name)) is not None}
        listed = {name: cmd for name, cmd in listed.items() if not cmd.hidden}
        sections: dict[str, list[tuple[str, str]]] = {}
        placed: set[str] = set()
        for heading, names in self.command_groups.items():
            for name in names:
                if name in listed:
                    sections.setdefault(heading, []).append((name, first_sentence(listed[name].help)))
                    placed.add(name)
        rest = [(name, first_sentence(cmd.help)) for name, cmd in listed.items() if name not in placed]
        if rest:
            sections.setdefault(OTHER_COMMANDS if sections else "Commands", []).extend(rest)
        for heading, rows in sections.items():
            with formatter.section(heading):
                formatter.write_dl(rows)


def use_plain_help(app: typer.Typer, command_groups: Mapping[str, tuple[str, ...]] | None = None) -> None:
    """Render ``app``'s help, its commands' and its sub-apps' in the plain style (call after every command is
    registered)."""
    group_cls = type("UnitacGroup", (PlainGroup,), {"command_groups": dict(command_groups or {})})
    app.rich_markup_mode = None
    if _unset(app.info.cls, TyperGroup):
        app.info.cls = group_cls
    for command in app.registered_commands:
        if _unset(command.cls, TyperCommand):
            command.cls = PlainCommand
    for group in app.registered_groups:
        if group.typer_instance is not None:
            use_plain_help(group.typer_instance)


def _unset(cls: Any, default: type) -> bool:
    """Whether a command's or group's class is typer's own (left for us to choose)."""
    return cls is None or cls is default or isinstance(cls, DefaultPlaceholder)
