"""The ``simspad`` command line (DESIGN §6).

Each subcommand is a thin wrapper: parse options, call one function of the module that owns the concept.
Bad input raises :class:`simspad.errors.SimSpadError`; :func:`main` prints its message on one line and exits
non-zero, with no traceback unless ``--debug`` is given.
"""

from __future__ import annotations

import sys
from pathlib import Path

import click

from simspad import __version__, defaults
from simspad.errors import SimSpadError

_DEBUG = False


def _parse_resolution(ctx, param, value):
    if value is None:
        return None
    try:
        w, h = (int(v) for v in value.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"expected WxH (for example 128x96), got {value!r}") from None
    if w <= 0 or h <= 0:
        raise click.BadParameter(f"width and height must be positive, got {value!r}")
    return (w, h)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="simspad")
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
def cli(debug: bool) -> None:
    """SimSPAD: physically rendered SPAD, frame and event datasets for low-light, high-speed imaging."""
    global _DEBUG
    _DEBUG = debug


@cli.command()
@click.argument("scene")
@click.argument("trajectory", required=False)
@click.option("--duration", "duration_s", type=float, required=True, help="Sequence duration in seconds.")
@click.option("--start", "start_s", type=float, default=0.0, show_default=True, help="Start time in seconds.")
@click.option("--resolution", callback=_parse_resolution, default="{}x{}".format(*defaults.RESOLUTION_PX), show_default=True,
              help="WxH pixels.")
@click.option("--spp", type=int, default=defaults.SPP, show_default=True, help="Samples per pixel.")
@click.option("--max-flow", "max_flow_px", type=float, default=defaults.MAX_FLOW_PX, show_default=True,
              help="Largest image motion between keyframes (pixels).")
@click.option("--min-rate", "min_rate_hz", type=float, default=defaults.MIN_KEYFRAME_RATE_HZ, show_default=True,
              help="Lowest keyframe rate (Hz), whatever the motion.")
@click.option("--seed", type=int, default=defaults.SEED, show_default=True, help="Render seed (frozen Monte Carlo noise).")
@click.option("--out", "out_dir", type=click.Path(path_type=Path), required=True, help="Render directory.")
def render(scene, trajectory, duration_s, start_s, resolution, spp, max_flow_px, min_rate_hz, seed, out_dir):
    """Render linear radiance keyframes of SCENE along TRAJECTORY (default: the scene's own)."""
    from simspad.cli.render import describe_render, render_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    summary = render_from_cli(scene, trajectory, duration_s=duration_s, start_s=start_s, resolution=resolution,
                              spp=spp, max_flow_px=max_flow_px, min_rate_hz=min_rate_hz, seed=seed,
                              out_dir=out_dir, progress=True)
    click.echo(describe_render(summary))


@cli.command()
@click.argument("render_dir", type=click.Path(path_type=Path))
@click.option("--lux", type=float, required=True, help="Scene illuminance in lux (> 0).")
@click.option("--sensors", default="spad,frames,events", show_default=True, help="Comma-separated sensor kinds.")
@click.option("--start", "start_s", type=float, default=None, help="Start time (s); default: first keyframe.")
@click.option("--duration", "duration_s", type=float, default=None, help="Duration (s); default: to the last keyframe.")
@click.option("--seed", type=int, default=defaults.SEED, show_default=True)
@click.option("--set", "overrides", multiple=True, metavar="SENSOR.FIELD=VALUE",
              help="Override a preset field, e.g. --set spad.gate_s=1e-6 (repeatable).")
@click.option("--out", "out_path", type=click.Path(path_type=Path), required=True, help="Recording (.h5).")
def simulate(render_dir, lux, sensors, start_s, duration_s, seed, overrides, out_path):
    """Simulate the sensors on a render directory at one lux level and write a recording."""
    from simspad.cli.simulate import simulate_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    path = simulate_from_cli(render_dir, lux=lux, sensors=sensors, start_s=start_s, duration_s=duration_s,
                             seed=seed, overrides=overrides, out_path=out_path)
    click.echo(f"wrote {path}")


@cli.command()
@click.argument("spec", required=False, type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=None, help="Output directory (default: the spec's).")
@click.option("--executor", type=click.Choice(["local", "dask"]), default="local", show_default=True)
@click.option("--scheduler", default=None, help="Address of a running Dask scheduler (dask executor).")
@click.option("--workers", type=int, default=None, help="Worker processes (default: from the core count).")
@click.option("--estimate", "estimate_only", is_flag=True,
              help="Print keyframes, CPU-hours, wall time, disk and peak memory (measured here) and stop.")
@click.option("--yes", "assume_yes", is_flag=True, help="Run even if the dataset will not fit the free disk.")
def generate(spec, out_dir, executor, scheduler, workers, estimate_only, assume_yes):
    """Generate a dataset from SPEC (default: the embedded datasets/mini.toml)."""
    from simspad.cli.generate import generate_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    generate_from_cli(spec, out_dir=out_dir, executor=executor, scheduler=scheduler, workers=workers,
                      estimate_only=estimate_only, assume_yes=assume_yes)


@cli.command()
@click.argument("target", type=click.Path(path_type=Path))
@click.option("--methods", default=None, help="Comma-separated method names (default: all that the data allows).")
@click.option("--out", "out_dir", type=click.Path(path_type=Path), required=True, help="Results directory.")
@click.option("--rate", "rate_hz", type=float, default=None, help="Evaluation rate in Hz (default: spec or 1000).")
def evaluate(target, methods, out_dir, rate_hz):
    """Run fusion methods and baselines on a dataset or recording and score them."""
    from simspad.cli.evaluate import evaluate_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    evaluate_from_cli(target, methods=methods, out_dir=out_dir, rate_hz=rate_hz)


@cli.command()
@click.argument("results_dirs", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=None, help="Output directory.")
def leaderboard(results_dirs, out_dir):
    """Build the leaderboard (markdown, csv, html with plots) from one or more results directories."""
    from simspad.cli.leaderboard import leaderboard_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    leaderboard_from_cli(results_dirs, out_dir=out_dir)


@cli.command()
@click.argument("submission", type=click.Path(path_type=Path))
@click.option("--dataset", "dataset_dir", type=click.Path(path_type=Path), required=True)
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=None, help="Results directory.")
def score(submission, dataset_dir, out_dir):
    """Score an external method's reconstructions (HDF5 submission) against a dataset."""
    from simspad.cli.score import score_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    score_from_cli(submission, dataset_dir=dataset_dir, out_dir=out_dir)


@cli.command()
@click.option("--out", "out_path", type=click.Path(path_type=Path), default=Path("snr.png"), show_default=True)
def snr(out_path):
    """Plot the analytic SNR versus photon flux of the three sensors."""
    from simspad.cli.snr import snr_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    snr_from_cli(out_path)


@cli.command()
@click.argument("path", type=click.Path(path_type=Path))
def info(path):
    """Summarise a spec (.toml), trajectory, recording (.h5) or dataset directory."""
    from simspad.cli.info import describe  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    click.echo(describe(path))


@cli.command()
@click.option("--contact-sheet", "contact_sheet", type=click.Path(path_type=Path), default=None,
              help="Render every built-in scene into one tone-mapped PNG.")
def scenes(contact_sheet):
    """List the built-in scenes and their default trajectories."""
    from simspad.cli.scenes import scenes_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    scenes_from_cli(contact_sheet=contact_sheet)


def main(argv: list[str] | None = None) -> int:
    """Entry point: run the CLI, turning user errors into one line on stderr and a non-zero exit."""
    try:
        cli.main(args=argv, standalone_mode=False)
    except SimSpadError as exc:
        if _DEBUG:
            raise
        click.echo(f"simspad: error: {exc.format()}", err=True)
        return exc.exit_code
    except click.exceptions.Abort:
        click.echo("simspad: aborted", err=True)
        return 130
    except click.ClickException as exc:
        exc.show()
        return exc.exit_code
    except KeyboardInterrupt:
        click.echo("simspad: interrupted", err=True)
        return 130
    except Exception as exc:  # a bug, not bad input: still one line unless --debug
        if _DEBUG:
            raise
        click.echo(f"simspad: internal error: {type(exc).__name__}: {exc} (run with --debug for the traceback)",
                   err=True)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
