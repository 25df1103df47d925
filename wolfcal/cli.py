"""The `wolfcal` command line: parse arguments, call one pipeline, print. No logic lives here."""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable

import typer

from wolfcal.errors import WolfcalError

app = typer.Typer(
    help="Kinematic calibration of humanoid robots: camera intrinsics, pose capture, fitting, evaluation.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def friendly_errors(command: Callable) -> Callable:
    """Turn WolfcalError (bad input) into a one-line message on stderr and a non-zero exit; Ctrl-C into exit 130."""

    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        try:
            return command(*args, **kwargs)
        except WolfcalError as exc:
            typer.secho(f"error: {exc}", fg=typer.colors.RED, err=True)
            raise typer.Exit(exc.exit_code) from None
        except KeyboardInterrupt:
            typer.secho("interrupted", err=True)
            raise typer.Exit(130) from None

    return wrapper


def main() -> None:
    app()


if __name__ == "__main__":
    sys.exit(main())
