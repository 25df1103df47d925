"""The `wolfcal` command line: parse arguments, call one pipeline, print. No logic lives here."""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
from pathlib import Path

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


DEFAULT_ROBOT = Path("configs/wolfgang")


@app.command()
@friendly_errors
def fit(
    captures: list[Path] = typer.Argument(..., help="Capture files (.mcap) to fit on."),
    robot: Path = typer.Option(DEFAULT_ROBOT, "--robot", help="Robot config (robot.yaml or its folder)."),
    free: str = typer.Option("camera", "--free", help="Free parameters: camera | head_camera | leg."),
    side: str = typer.Option("both", "--side", help="Leg preset: right | left | both."),
    fix_tags: bool = typer.Option(False, "--fix-tags", help="Hold the tag mounts at their configured poses."),
    intrinsics: Path | None = typer.Option(None, "--intrinsics", help="camera_info YAML overriding the capture's."),
    out: Path = typer.Option(..., "--out", help="Output folder for result.yaml and calibrated.urdf."),
) -> None:
    """Estimate the chosen free parameters from one or more captures."""
    from wolfcal.fit.pipeline import FitOptions, run_fit

    run_fit(captures, robot, out, FitOptions(free=free, side=side, fix_tags=fix_tags), intrinsics, say=typer.echo)


@app.command()
@friendly_errors
def simulate(
    out: Path = typer.Option(..., "--out", help="Capture file to write (.mcap); truth goes beside it."),
    robot: Path = typer.Option(DEFAULT_ROBOT, "--robot", help="Robot config (robot.yaml or its folder)."),
    samples: int = typer.Option(24, "--samples", help="Number of still poses."),
    seed: int = typer.Option(0, "--seed", help="Random seed (same seed, same capture)."),
    offsets: str = typer.Option("none", "--offsets", help="Joints with true encoder offsets: none|head|legs|all."),
    binning: int = typer.Option(1, "--binning", help="Sensor binning (4 gives 512x384 images of a 2048x1536 camera)."),
    noise: float = typer.Option(2.0, "--noise", help="Image noise standard deviation [gray levels]."),
    outliers: float = typer.Option(0.0, "--outliers", help="Share of outlier samples (motion blur, stale joints)."),
    intrinsics: Path | None = typer.Option(None, "--intrinsics", help="camera_info YAML (default: the config's)."),
) -> None:
    """Write a simulated capture with known ground truth (FILE.mcap, FILE.truth.yaml, FILE.truth.urdf)."""
    from wolfcal.camera.camera_info import load_camera_info
    from wolfcal.sim.simulate import SimOptions, simulate_capture

    options = SimOptions(
        samples=samples, seed=seed, binning=binning, noise_sigma=noise, outlier_fraction=outliers, offsets=offsets
    )
    camera = load_camera_info(intrinsics) if intrinsics else None
    simulate_capture(robot, out, options, camera, say=typer.echo)


def main() -> None:
    app()


if __name__ == "__main__":
    sys.exit(main())
