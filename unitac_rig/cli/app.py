"""The ``unitac-rig`` command line.

Each area registers its own commands from a ``cli_*`` module, so this file stays a short table of contents.
Errors from the project's exception tree become one clear line and exit code 1 (2 for usage and configuration
errors); ``--debug`` shows the traceback instead, with the same exit code.
"""

from __future__ import annotations

import contextlib
import importlib
import logging
import signal
import sys
import traceback
from typing import NoReturn

import typer

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

# Modules that add commands to ``app`` through a ``register(app)`` function, in help order.
COMMAND_MODULES = (
    "unitac_rig.cli.collect",  # collect, campaign, extract, objects
    "unitac_rig.cli.dataset",  # inspect [--watch], export, verify
    "unitac_rig.cli.learn_train",  # train
    "unitac_rig.cli.learn",  # report, translate, geometry, export-model
    "unitac_rig.cli.probe",  # probe uskin|papillarray|ur5e
    "unitac_rig.cli.import_unitac_nv",  # import-unitac-nv
    "unitac_rig.cli.bench",  # bench ...
    "unitac_rig.cli.twin",  # twin (the real-time twin of the rig)
    "unitac_rig.cli.stream",  # stream (a trained run on the live sensor)
    "unitac_rig.cli.view",  # view (a session or a live sensor in Rerun)
)

# The root help lists the commands under these headings, in this order (a command not named here is listed last).
COMMAND_GROUPS = {
    "Collect data": ("collect", "campaign", "extract", "objects"),
    "Look at and share data": ("inspect", "view", "export", "verify", "import-unitac-nv"),
    "Learn": ("train", "report", "translate", "geometry", "export-model"),
    "Devices and the simulated rig": ("probe", "twin", "bench"),
}

_state = {"debug": False}


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
    _state["debug"] = debug
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


for _module in COMMAND_MODULES:
    importlib.import_module(_module).register(app)
use_plain_help(app, COMMAND_GROUPS)


def main(argv: list[str] | None = None) -> None:
    """Console entry point: run the app, mapping every error to one line and a non-zero exit.

    Usage errors (unknown command or option, missing or bad value, a path that is not what the option needs, a rig
    or configuration file that does not validate) exit 2, also with ``--debug`` (which shows the traceback), and
    so does no command at all (the help is printed); other project errors 1, Ctrl-C 130,
    SIGTERM / SIGHUP during a collection 143 / 129 (after the same clean stop as Ctrl-C).
    Only names typer itself exports are used here: typer 0.29 dropped its click dependency, so importing click
    (which is not declared) broke this very path on a fresh install.
    """
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
        if debug:
            raise
        typer.secho(
            f"error: unexpected {type(exc).__name__}: {exc} (rerun with --debug for details)",
            err=True,
            fg=typer.colors.RED,
        )
        sys.exit(1)
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
