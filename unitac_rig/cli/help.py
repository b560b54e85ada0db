"""Help pages in the plain style of git/pip-era tools, readable at 80 columns.

typer's rich help boxes every option in six columns, which leaves the description about 18 columns at 80 and cuts
words. Here: one option per row, its description wrapped beside it; flags without a placeholder, options with one
UPPERCASE word; ``[default: X]`` (``show_default="..."`` where the value comes from elsewhere); options under their
``rich_help_panel`` heading, commands under the headings of :data:`unitac_rig.cli.app.COMMANDS`. Only public typer
classes are subclassed; the app sets ``rich_markup_mode=None`` so they render through the plain formatter.
"""

from __future__ import annotations

import inspect
from collections.abc import Iterable, Mapping
from typing import Any

import typer
from pydantic.fields import FieldInfo
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


def field_flag(name: str, info: FieldInfo) -> str | None:
    """The option that sets the pydantic field ``name``: its ``cli`` extra (None: no option), else ``--name-dashed``."""
    extra = info.json_schema_extra if isinstance(info.json_schema_extra, dict) else {}
    flag = extra.get("cli", "--" + name.replace("_", "-"))
    return None if flag is None else str(flag)


def field_bounds(info: FieldInfo) -> dict[str, Any]:
    """A pydantic field's bounds by their annotated_types names (gt, ge, lt, le); a whole float as an int, so the
    help says "at least 0"."""
    bounds = {name: getattr(m, name) for m in info.metadata for name in ("gt", "ge", "lt", "le") if hasattr(m, name)}
    return {k: int(v) if isinstance(v, float) and v.is_integer() else v for k, v in bounds.items()}


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
    return f"at least {low}" if low is not None else (f"at most {high}" if high is not None else None)


def _argument_name(param: TyperArgument) -> str:
    return placeholder(param) + ("..." if param.nargs != 1 else "")


def help_record(param: Any) -> tuple[str, str]:
    """(the option as typed, its description with [default: ...] / [required] / range) for one parameter."""
    if isinstance(param, TyperArgument):
        return _argument_name(param), (param.help or "") + ("" if param.required else "  [optional]")
    names = ", ".join(param.opts) + (" / " + ", ".join(param.secondary_opts) if param.secondary_opts else "")
    if not param.is_flag and not getattr(param, "count", False):
        names += " " + placeholder(param)
    default = None if param.required else _default_text(param)
    extra = [f"default: {default}"] if default is not None else []
    extra += [text for text in (_range_text(param), "required" if param.required else None) if text]
    text = inspect.cleandoc(param.help or "")
    if extra:
        text = f"{text}  [{'; '.join(extra)}]".lstrip()
    return names, text


def write_params(params: Iterable[Any], formatter: Any) -> None:
    """Arguments first, then options in their groups, the general ones first, then the others in the order their
    group first appears."""
    groups: dict[str, list[tuple[str, str]]] = {"Arguments": [], OPTIONS_HEADING: []}
    for param in params:
        if not getattr(param, "hidden", False):
            heading = "Arguments" if isinstance(param, TyperArgument) else getattr(param, "rich_help_panel", None)
            groups.setdefault(heading or OPTIONS_HEADING, []).append(help_record(param))
    _write_sections(groups, formatter)


def _write_sections(sections: Mapping[str, list[tuple[str, str]]], formatter: Any) -> None:
    for heading, rows in sections.items():
        if rows:
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


class PlainCommand(TyperCommand):
    """A command whose help is plain text: grouped options, one placeholder and default style, no cut words."""

    def collect_usage_pieces(self, ctx: Any) -> list[str]:
        """``[OPTIONS] RUN INPUT``: the arguments by their placeholders (typer wrote ``{run}``)."""
        pieces = [self.options_metavar] if self.options_metavar else []
        for param in self.get_params(ctx):
            if isinstance(param, TyperArgument):
                pieces.append(_argument_name(param) if param.required else f"[{_argument_name(param)}]")
        return pieces

    def format_options(self, ctx: Any, formatter: Any) -> None:
        write_params(self.get_params(ctx), formatter)


class PlainGroup(TyperGroup):
    """A command group whose help lists its options, then its commands under the headings of ``command_groups``."""

    command_groups: Mapping[str, tuple[str, ...]] = {}

    def format_options(self, ctx: Any, formatter: Any) -> None:
        write_params(self.get_params(ctx), formatter)
        self.format_commands(ctx, formatter)

    def format_commands(self, ctx: Any, formatter: Any) -> None:
        listed = {name: cmd for name in self.list_commands(ctx) if (cmd := self.get_command(ctx, name)) is not None}
        rows = {name: (name, first_sentence(cmd.help)) for name, cmd in listed.items() if not cmd.hidden}
        sections = {heading: [rows[n] for n in names if n in rows] for heading, names in self.command_groups.items()}
        placed = {name for names in self.command_groups.values() for name in names}
        rest = [row for name, row in rows.items() if name not in placed]
        if rest:
            sections.setdefault(OTHER_COMMANDS if sections else "Commands", []).extend(rest)
        _write_sections(sections, formatter)


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
