"""The ``unitac-rig`` command line: the table of its commands (each defined in the module of its area).

Errors from the project's exception tree become one clear line and exit code 1 (2 for usage and configuration
errors); ``--debug`` shows the traceback instead, with the same exit code.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import sys
import traceback
from typing import Any, NoReturn

import typer

from unitac_rig.cli import bench, collect, dataset, import_unitac_nv, learn, learn_train, probe, stream, twin, view
from unitac_rig.cli.help import use_plain_help
from unitac_rig.errors import ConfigError, UnitacError, UsageError
from unitac_rig.interrupts import last_termination_signal, termination_signal
from unitac_rig.provenance import package_version

app = typer.Typer(
    name="unitac-rig",
    help="Collect cross-sensor tactile data on a UR5e press rig (or its simulated twin) and learn a shared "
    "representation (UniTac-NV).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # plain help, readable at 80 columns (see cli/help.py)
)

# Every command under the heading the root help lists it by, in order (a typer app is a group of subcommands).
COMMANDS: dict[str, dict[str, Any]] = {
    "Collect data": {
        "collect": collect.collect,
        "campaign": collect.campaign,
        "extract": collect.extract,
        "objects": collect.objects_cmd,
    },
    "Look at and share data": {
        "inspect": dataset.inspect,
        "view": view.view_command,
        "export": dataset.export,
        "verify": dataset.verify,
        "import-unitac-nv": import_unitac_nv.import_unitac_nv_command,
    },
    "Learn": {
        "train": learn_train.train_command,
        "report": learn.report_command,
        "translate": learn.translate_command,
        "geometry": learn.geometry_command,
        "export-model": learn.export_model_command,
    },
    "Devices and the simulated rig": {"probe": probe.probe_app, "twin": twin.twin, "bench": bench.bench_app},
    "Other commands": {"stream": stream.stream_command},
}


def _show_version(value: bool) -> None:
    if value:
        typer.echo(f"unitac-rig {package_version()}")
        raise typer.Exit(0)


@app.callback()
def _root(
    debug: bool = typer.Option(
        False, "--debug", help="Show full tracebacks and debug logging (also after the command)."
    ),
    version: bool = typer.Option(
        False, "--version", callback=_show_version, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    handler = logging.StreamHandler()
    handler.setFormatter(_LogLine() if not debug else logging.Formatter(LOG_FORMAT))
    logging.basicConfig(level=logging.DEBUG if debug else logging.WARNING, handlers=[handler])


LOG_FORMAT = "%(levelname)s %(name)s: %(message)s"


class _LogLine(logging.Formatter):
    """A log record as one line: the exception's own message instead of its traceback (``--debug`` shows those)."""

    def format(self, record: logging.LogRecord) -> str:
        text = f"{record.levelname} {record.name}: {record.getMessage()}"
        if record.exc_info and record.exc_info[1] is not None:
            text += f" ({record.exc_info[1]})"
        return text


for _commands in COMMANDS.values():
    for _name, _command in _commands.items():
        if isinstance(_command, typer.Typer):
            app.add_typer(_command, name=_name)
        else:
            app.command(_name)(_command)
use_plain_help(app, {heading: tuple(commands) for heading, commands in COMMANDS.items()})


def main(argv: list[str] | None = None) -> None:
    """Console entry point: every error one line and a non-zero exit (the traceback too with ``--debug``): 2 for a
    usage error (and no command at all: the help), 1 other project errors, 130 Ctrl-C, 143 / 129 SIGTERM / SIGHUP.
    Only names typer itself exports are used: typer 0.29 dropped its click dependency (click is not declared)."""
    args = hoist_debug(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in args
    try:
        result = app(args=args, standalone_mode=False)
    except UnitacError as exc:
        _fail(debug, f"error: {exc.one_line()}", 2 if isinstance(exc, (UsageError, ConfigError)) else 1)
    except typer.Exit as exc:
        sys.exit(exc.exit_code)
    except (KeyboardInterrupt, typer.Abort) as exc:
        _interrupted(termination_signal(exc))
    except typer.TyperException as exc:  # typer's usage errors: unknown command/option, bad or missing value
        if type(exc).__name__ == "NoArgsIsHelpError":  # `unitac-rig` (or a command group) alone: its help, exit 2
            ctx = getattr(exc, "ctx", None)
            typer.echo(ctx.get_help() if ctx is not None else _usage_line(exc))
            sys.exit(2)
        _fail(debug, f"error: {_usage_line(exc)}", getattr(exc, "exit_code", 2))
    except Exception as exc:
        _fail(debug, f"error: unexpected {type(exc).__name__}: {exc} (rerun with --debug for details)", 1)
    # Without standalone mode typer *returns* an exit code instead of raising: typer.Exit(n) from a command, and
    # 130 for a KeyboardInterrupt (Ctrl-C, or SIGTERM/SIGHUP during collect), which it catches itself.
    if isinstance(result, int) and result != 0:
        if result == 130:
            _interrupted(last_termination_signal())
        sys.exit(result)


def _fail(debug: bool, line: str, code: int) -> NoReturn:
    """End a failed command with ``code``: one red line, or with ``--debug`` the traceback (the same exit code,
    so a script sees the same status either way)."""
    if debug:
        traceback.print_exc()
    else:
        typer.secho(line, err=True, fg=typer.colors.RED)
    sys.exit(code)


def hoist_debug(args: list[str]) -> list[str]:
    """``--debug`` is accepted anywhere before a ``--``: moved in front of the command, where the app reads it."""
    end = args.index("--") if "--" in args else len(args)
    if "--debug" not in args[:end]:
        return list(args)
    return ["--debug", *(a for a in args[:end] if a != "--debug"), *args[end:]]


def _interrupted(number: int | None) -> None:
    """One line and the exit status of an interrupt: 130 for Ctrl-C, 128 + the signal for SIGTERM / SIGHUP."""
    with contextlib.suppress(OSError):  # after SIGHUP the terminal may be gone
        typer.secho(f"terminated ({signal.Signals(number).name})" if number else "interrupted", err=True)
    sys.exit(128 + number if number else 130)


def _usage_line(exc: Exception) -> str:
    """typer's own message for a usage error, on one line, with where to look for help."""
    format_message = getattr(exc, "format_message", None)
    message = format_message() if callable(format_message) else str(exc)
    message = " ".join(str(message).split())
    ctx = getattr(exc, "ctx", None)
    command_path = getattr(ctx, "command_path", None) or "unitac-rig"
    return f"{message} (see '{command_path} --help')"
