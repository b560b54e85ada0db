"""The ``unitac-rig`` command line.

Each area registers its own commands from a ``cli_*`` module, so this file stays a short table of contents.
Errors from the project's exception tree become one clear line and exit code 1 (2 for usage errors);
``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import importlib
import logging
import sys

import typer

from protocols.errors import UnitacError

app = typer.Typer(
    name="unitac-rig",
    help="Collect cross-sensor tactile data on a UR5e press rig (or its simulated twin) and learn a shared "
    "representation (UniTac-NV).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

# Modules that add commands to ``app`` through a ``register(app)`` function, in help order.
COMMAND_MODULES = (
    "unitac_rig.cli_collect",  # collect, campaign, inspect, extract
    "unitac_rig.cli_learn",  # train, translate, geometry
    "unitac_rig.cli_probe",  # probe uskin|papillarray|ur5e
    "unitac_rig.cli_import",  # import-unitac-nv
    "unitac_rig.cli_bench",  # bench ...
)

_state = {"debug": False}


@app.callback()
def _root(
    debug: bool = typer.Option(False, "--debug", help="Show full tracebacks and debug logging."),
) -> None:
    _state["debug"] = debug
    logging.basicConfig(
        level=logging.DEBUG if debug else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )


for _module in COMMAND_MODULES:
    importlib.import_module(_module).register(app)


def main(argv: list[str] | None = None) -> None:
    """Console entry point: run the app, mapping project errors to one line and a non-zero exit."""
    args = sys.argv[1:] if argv is None else argv
    debug = "--debug" in args
    try:
        app(args=args, standalone_mode=False)
    except UnitacError as exc:
        if debug:
            raise
        typer.secho(f"error: {exc.one_line()}", err=True, fg=typer.colors.RED)
        sys.exit(2 if type(exc).__name__ == "UsageError" else 1)
    except KeyboardInterrupt:
        typer.secho("interrupted", err=True)
        sys.exit(130)
    except Exception as exc:  # click usage errors and the like
        import click

        if isinstance(exc, click.exceptions.Exit):
            sys.exit(exc.exit_code)
        if isinstance(exc, click.ClickException):
            exc.show()
            sys.exit(exc.exit_code)
        if isinstance(exc, click.exceptions.Abort):
            typer.secho("aborted", err=True)
            sys.exit(130)
        if debug:
            raise
        typer.secho(
            f"error: unexpected {type(exc).__name__}: {exc} (rerun with --debug for details)",
            err=True,
            fg=typer.colors.RED,
        )
        sys.exit(1)
