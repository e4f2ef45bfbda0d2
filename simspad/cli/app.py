"""The ``simspad`` command line (README.md).

Each subcommand is a thin wrapper: parse options, call one function of the module that owns the concept.
Bad input raises :class:`simspad.errors.SimSpadError`; :func:`main` prints its message on one line and exits
non-zero, with no traceback unless ``--debug`` is given.
"""

from __future__ import annotations

import errno
import os
import sys
from pathlib import Path

import click

from simspad import __version__, defaults
from simspad.cli.interrupt import Terminated, first_sigint_only, sigterm_raises
from simspad.cli.library_noise import quiet_library_warnings
from simspad.errors import SimSpadError
from simspad.io.export import FORMATS as EXPORT_FORMATS
from simspad.io.export import FRAME_FORMATS as EXPORT_FRAME_FORMATS
from simspad.io.export import PACKINGS as EXPORT_PACKINGS

_DEBUG = False
#: The built-in method names for ``--help`` (not imported from the registry: `simspad --help` stays fast;
#: tests/evaluate/test_cli_help.py checks it against the registry).
METHOD_NAMES_HELP = "nedi_akf, adaptive_nedi_akf, akf_fe, cf, edi, ni, nedi, qbp"


class _TableHelpOption(click.Option):
    """An option whose help text is written when help is shown, by ``table_help()`` from the sensor table:
    importing the table (simulators, plugins) at start-up would cost every command, ``simspad --help`` too, 0.3 s."""

    def __init__(self, *args, table_help, **kwargs):
        super().__init__(*args, **kwargs)
        self._table_help = table_help

    def get_help_record(self, ctx):
        self.help = self._table_help()
        return super().get_help_record(ctx)


def _sensors_help() -> str:
    from simspad.sensors.registry import BUILTIN_SENSORS, SENSORS  # deferred: see _TableHelpOption

    return (f"Comma-separated sensor kinds, of: {', '.join(SENSORS)}.  "
            f"[default: {','.join(row.name for row in BUILTIN_SENSORS)}]")


def _set_help() -> str:
    from simspad.sensors.registry import SENSORS  # deferred: see _TableHelpOption

    presets = "; ".join(f"{kind} {', '.join(row.presets)}" for kind, row in SENSORS.items())
    return ("Override a preset field, e.g. --set spad.gate_s=1e-6 (repeatable; presets: " + presets
            + " — `simspad info` on a recording lists every field).")


def _parse_resolution(ctx, param, value):
    """``WxH`` text to two integers; their values are checked by :class:`~simspad.render.settings.RenderSettings`."""
    if value is None:
        return None
    try:
        w, h = (int(v) for v in value.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"expected WxH (for example 128x96), got {value!r}") from None
    return (w, h)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="simspad")
@click.option("--debug", is_flag=True, help="Show full tracebacks on errors.")
@click.option("--allow-python-scenes", "allow_python_scenes", is_flag=True,
              help="Run users' scene folders that hold scene.py (Python code); off by default.")
def cli(debug: bool, allow_python_scenes: bool) -> None:
    """SimSPAD: physically rendered SPAD, frame and event datasets for low-light, high-speed imaging."""
    global _DEBUG
    _DEBUG = debug
    quiet_library_warnings(debug)  # numpy/matplotlib/resource-tracker warnings are not for the user
    if allow_python_scenes:
        os.environ["SIMSPAD_ALLOW_PYTHON_SCENES"] = "1"  # inherited by render and simulation workers
    from simspad.io.provenance import source_date_epoch  # deferred: `simspad --help` stays 0.25 s

    source_date_epoch()  # a malformed $SOURCE_DATE_EPOCH is one line now, not a crash inside a later import


@cli.command()
@click.argument("scene")
@click.argument("trajectory", required=False)
@click.option("--duration", "duration_s", type=float, required=True, help="Sequence duration in seconds.")
@click.option("--start", "start_s", type=float, default=0.0, show_default=True, help="Start time in seconds.")
@click.option("--resolution", callback=_parse_resolution, default="{}x{}".format(*defaults.RESOLUTION_PX), show_default=True,
              help="WxH pixels.")
@click.option("--spp", type=int, default=None,
              help=f"Samples per pixel: path tracing (the reference) at N samples; with --convergence cache, camera "
                   f"rays per pixel. [default: {defaults.CAMERA_RAYS} camera rays, converged ({defaults.FEW_CAMERA_RAYS} from "
                   f"{defaults.FEW_CAMERA_RAYS_FROM_PX} px wide); {defaults.SPP} with --convergence off]")
@click.option("--max-flow", "max_flow_px", type=float, default=defaults.MAX_FLOW_PX, show_default=True,
              help="Largest image motion between keyframes (pixels).")
@click.option("--min-rate", "min_rate_hz", type=float, default=defaults.MIN_KEYFRAME_RATE_HZ, show_default=True,
              help="Lowest keyframe rate (Hz), whatever the motion.")
@click.option("--seed", type=int, default=defaults.SEED, show_default=True, help="Render seed (frozen Monte Carlo noise).")
@click.option("--interpolation", type=click.Choice(["warp", "linear"]), default="linear", show_default=True,
              help="linear: render every keyframe; warp (experimental): render every 16th keyframe and synthesize the "
                   "rest by reprojection (directly seen emitters rendered, reflected light warped), rendering blocks or "
                   "whole keyframes where the warps disagree — 1.0–3.6x less render work on the built-in scenes at 64 "
                   "spp, with more events than linear on the office (docs/rendering.md).")
@click.option("--gt-rate", "gt_rate_hz", type=float, default=defaults.GT_RATE_HZ, show_default=True,
              help="Ground-truth rate (Hz): a geometry pass (depth, instance ids at the pixel centres) is rendered at "
                   "ground-truth instant, for the recordings' masks and motion field (`simspad simulate` records "
                   "ground truth at the default rate; `simspad generate` renders at its evaluation.rate_hz).")
@click.option("--convergence", type=click.Choice(["auto", "off", "cache"]), default="auto", show_default=True,
              help="cache: converge the diffuse light once into a world-space irradiance cache and trace only --spp "
                   "camera rays per pixel through their glossy bounces (median error <= 3 % against a 4096-spp "
                   "reference on every built-in scene; docs/rendering.md, converged radiance); off: path-trace every "
                   "pixel of every keyframe at --spp (Monte Carlo noise that changes between keyframes: the "
                   "reference at high --spp); auto: cache, unless --spp is given.")
@click.option("--cache-samples", type=int, default=1024, show_default=True,
              help="With --convergence cache: irradiance estimates per point of the cache's probe views.")
@click.option("--out", "out_dir", type=click.Path(path_type=Path), required=True,
              help="Render directory: new, empty, or a render directory (its cached keyframes are re-used).")
def render(scene, trajectory, duration_s, start_s, resolution, spp, max_flow_px, min_rate_hz, seed, interpolation,
           gt_rate_hz, convergence, cache_samples, out_dir):
    """Render linear radiance keyframes of SCENE along TRAJECTORY (default: the scene's own).

    SCENE is a built-in scene (fan, office, piano, plant, siemens-star: `simspad scenes` lists them) or a folder
    holding a Mitsuba 3 scene.
    """
    from simspad.cli.render import describe_render, render_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    if convergence == "auto":  # `--spp N` alone keeps meaning brute-force path tracing: the reference
        convergence = "off" if spp is not None else "cache"
    if spp is None:
        spp = defaults.camera_rays(resolution[0]) if convergence == "cache" else defaults.SPP
    summary = render_from_cli(scene, trajectory, duration_s=duration_s, start_s=start_s, resolution=resolution,
                              spp=spp, max_flow_px=max_flow_px, min_rate_hz=min_rate_hz, seed=seed,
                              interpolation=interpolation, gt_rate_hz=gt_rate_hz, convergence=convergence,
                              cache_samples=cache_samples, out_dir=out_dir, progress=True)
    click.echo(describe_render(summary))


@cli.command()
@click.argument("render_dir", type=click.Path(path_type=Path))
@click.option("--lux", type=float, required=True, help="Scene illuminance in lux (> 0).")
@click.option("--sensors", default=None, cls=_TableHelpOption, table_help=_sensors_help)
@click.option("--start", "start_s", type=float, default=None, help="Start time (s); default: first keyframe.")
@click.option("--duration", "duration_s", type=float, default=None, help="Duration (s); default: to the last keyframe.")
@click.option("--seed", type=int, default=defaults.SEED, show_default=True)
@click.option("--set", "overrides", multiple=True, metavar="SENSOR.FIELD=VALUE", cls=_TableHelpOption,
              table_help=_set_help)
@click.option("--gt-rate", "gt_rate_hz", type=float, default=None,
              help="Ground-truth rate (Hz); default: the render's geometry-pass rate (its masks and motion field are "
                   "recorded at those instants), else 1000.")
@click.option("--out", "out_path", type=click.Path(path_type=Path), required=True, help="Recording (.h5).")
def simulate(render_dir, lux, sensors, start_s, duration_s, seed, overrides, gt_rate_hz, out_path):
    """Simulate the sensors on a render directory at one lux level and write a recording."""
    from simspad.cli.simulate import simulate_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    path = simulate_from_cli(render_dir, lux=lux, sensors=sensors, start_s=start_s, duration_s=duration_s,
                             seed=seed, overrides=overrides, out_path=out_path, gt_rate_hz=gt_rate_hz)
    click.echo(f"wrote {path}")


@cli.command()
@click.argument("spec", required=False)
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=None,
              help="Output directory (default: the spec's `output`, e.g. output/mini).")
@click.option("--executor", type=click.Choice(["local", "dask"]), default="local", show_default=True)
@click.option("--scheduler", default=None, help="Address of a running Dask scheduler (dask executor).")
@click.option("--workers", type=int, default=None, help="Worker processes (default: from the core count).")
@click.option("--prune", is_flag=True, help="Delete recordings and renders that the changed spec no longer lists.")
@click.option("--estimate", "estimate_only", is_flag=True,
              help="Print keyframes, CPU-hours, wall time, disk and peak memory (measured here) and stop.")
@click.option("--yes", "assume_yes", is_flag=True, help="Run even if the dataset will not fit the free disk.")
def generate(spec, out_dir, executor, scheduler, workers, prune, estimate_only, assume_yes):
    """Generate a dataset from SPEC: a spec file or a bundled spec's name (default: mini).

    Bundled specs: mini (the default, minutes on a laptop), simspad (paper scale).
    """
    from simspad.cli.generate import generate_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    generate_from_cli(spec, out_dir=out_dir, executor=executor, scheduler=scheduler, workers=workers, prune=prune,
                      estimate_only=estimate_only, assume_yes=assume_yes)


@cli.command()
@click.argument("target", type=click.Path(path_type=Path))
@click.option("--methods", default=None, help="Comma-separated method names, from: " + METHOD_NAMES_HELP +
              " (default: the spec's evaluation.methods, else all that the data allows).")
@click.option("--out", "out_dir", type=click.Path(path_type=Path), required=True,
              help="Results directory (required; no default): new, empty, or one `evaluate` wrote before, whose "
                   "own files are replaced and others kept.")
@click.option("--rate", "rate_hz", type=float, default=None, help="Evaluation rate in Hz (default: spec or 1000).")
@click.option("--param", "params", multiple=True, metavar="METHOD.NAME=VALUE",
              help="Set a method's parameter, e.g. --param nedi_akf.aggregate_hz=800 (repeatable; over the spec's "
                   "[evaluation.params.METHOD]; docs/methods.md lists each method's).")
def evaluate(target, methods, out_dir, rate_hz, params):
    """Run fusion methods and baselines on a dataset or recording and score them."""
    from simspad.cli.evaluate import evaluate_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    evaluate_from_cli(target, methods=methods, out_dir=out_dir, rate_hz=rate_hz, params=params)


@cli.command()
@click.argument("results_dirs", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=None,
              help="Output directory (default: the first RESULTS_DIR).")
def leaderboard(results_dirs, out_dir):
    """Build the leaderboard (markdown, csv, html with plots) from one or more results directories."""
    from simspad.cli.leaderboard import leaderboard_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    leaderboard_from_cli(results_dirs, out_dir=out_dir)


@cli.command()
@click.argument("submission", type=click.Path(path_type=Path))
@click.option("--dataset", "dataset_dir", type=click.Path(path_type=Path), required=True,
              help="Dataset directory (with manifest.json) the submission reconstructs (required).")
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=None,
              help="Results directory (default: <SUBMISSION stem>_results beside the submission).")
def score(submission, dataset_dir, out_dir):
    """Score an external method's reconstructions (HDF5 submission) against a dataset."""
    from simspad.cli.score import score_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    score_from_cli(submission, dataset_dir=dataset_dir, out_dir=out_dir)


@cli.command()
@click.option("--out", "out_path", type=click.Path(path_type=Path), default=Path("output/snr.png"), show_default=True,
              help="Figure (PNG).")
def snr(out_path):
    """Plot the analytic SNR versus photon flux of the three sensors."""
    from simspad.cli.snr import snr_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    snr_from_cli(out_path)


@cli.command()
@click.argument("path")
def info(path):
    """Summarise a spec (.toml or a bundled name: mini, simspad), trajectory, recording (.h5) or dataset directory.

    Exit status 1 when a dataset's recording no longer matches the sha256 its manifest records."""
    from simspad.cli.info import info_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    info_from_cli(path)


@cli.command()
@click.option("--contact-sheet", "contact_sheet", type=click.Path(path_type=Path), default=None,
              help="Also render every built-in scene into this tone-mapped PNG (e.g. output/scenes.png).")
def scenes(contact_sheet):
    """List the built-in scenes and their default trajectories."""
    from simspad.cli.scenes import scenes_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    scenes_from_cli(contact_sheet=contact_sheet)


@cli.command()
@click.argument("target", type=click.Path(path_type=Path))
@click.option("--out", "out_path", type=click.Path(path_type=Path), required=True,
              help="preview.mp4, .gif or .png (a strip of 5 instants); for a dataset, a folder (one file per "
                   "recording, named by its key, with --kind's suffix).")
@click.option("--kind", type=click.Choice(["mp4", "gif", "png"]), default="mp4", show_default=True,
              help="For a dataset: the kind of each recording's preview.")
@click.option("--start", "start_s", type=float, default=None, help="First instant shown, s (default: the start).")
@click.option("--duration", "duration_s", type=float, default=None, help="Span shown, s (default: all).")
@click.option("--slowdown", type=float, default=100.0, show_default=True,
              help="Video seconds per recording second.")
@click.option("--fps", type=float, default=25.0, show_default=True, help="Video frames per second.")
@click.option("--spad-rate", "spad_rate_hz", type=float, default=1000.0, show_default=True,
              help="Aggregate rate of the SPAD panel, Hz.")
@click.option("--event-window-ms", type=float, default=1.0, show_default=True,
              help="Accumulation window of the events panel, ms.")
def preview(target, out_path, kind, start_s, duration_s, slowdown, fps, spad_rate_hz, event_window_ms):
    """Watch a recording (or every recording of a dataset): ground truth, SPAD, frames and events side by side."""
    from simspad.cli.preview import preview_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    preview_from_cli(target, out_path, kind=kind, start_s=start_s, duration_s=duration_s, slowdown=slowdown,
                     fps=fps, spad_rate_hz=spad_rate_hz, event_window_s=event_window_ms * 1e-3)


@cli.command(name="export")
@click.argument("recording", type=click.Path(path_type=Path))
@click.option("--to", "fmt", type=click.Choice(list(EXPORT_FORMATS)), required=True,
              help="; ".join(f"{k}: {v}" for k, v in EXPORT_FORMATS.items()) + ".")
@click.option("--out", "out_path", type=click.Path(path_type=Path), required=True,
              help="File to write (dsec .h5, aedat4 .aedat4, evt3 .raw) or directory (npz, dsec-flow); an existing "
                   "one is replaced only if it is an earlier export of the same format.")
@click.option("--spad-packing", "packing", type=click.Choice(list(EXPORT_PACKINGS)), default="packed",
              show_default=True, help="npz: SPAD bits 8 pixels a byte (as stored) or one uint8 0/1 per pixel.")
@click.option("--frames-format", type=click.Choice(list(EXPORT_FRAME_FORMATS)), default="png", show_default=True,
              help="npz: one 16-bit PNG per frame, or one multi-page TIFF stack.")
@click.option("--flow-stride", type=click.IntRange(min=1), default=1, show_default=True,
              help="dsec-flow: ground-truth intervals per flow map (DSEC's maps span 100 ms: 100 at 1 kHz).")
def export(recording, fmt, out_path, packing, frames_format, flow_stride):
    """Export RECORDING (.h5) to a format other tools read (DSEC, AEDAT 4, EVT 3.0, npz/PNG/EXR, DSEC flow)."""
    from simspad.cli.export import export_from_cli  # deferred: `simspad --help` stays 0.25 s (pipeline: 1–3 s)

    export_from_cli(recording, fmt, out_path, packing=packing, frames_format=frames_format,
                    flow_stride=flow_stride)


@cli.command(name="import")
@click.argument("calibration", type=click.Path(path_type=Path))
@click.option("--out", "out_path", type=click.Path(path_type=Path), required=True,
              help="Recording to write (.h5).")
@click.option("--spad-compression", "compression", type=click.Choice(["zstd", "gzip", "none"]), default="zstd",
              show_default=True, help="Storage filter of /spad/bits.")
@click.option("--no-progress", is_flag=True, help="No progress bars.")
def import_(calibration, out_path, compression, no_progress):
    """Build a recording from real captures described by CALIBRATION (.toml; docs/format.md section 9)."""
    from simspad.cli.import_captures import import_from_cli  # deferred: `simspad --help` stays 0.25 s

    import_from_cli(calibration, out_path, compression=compression, progress=not no_progress)


def main(argv: list[str] | None = None) -> int:
    """Entry point: run the CLI, turning user errors into one line on stderr and a non-zero exit.

    Without ``argv`` (the ``simspad`` program: its arguments are ``sys.argv``) the process exits next, and a Ctrl-C
    from the end of the command on is ignored (:func:`~simspad.cli.interrupt.first_sigint_only`); with ``argv``
    (a caller inside its own process) the caller's SIGINT handler is put back. SIGTERM runs the same clean-up as
    Ctrl-C and ends the command with status 143 (:func:`~simspad.cli.interrupt.sigterm_raises`).
    """
    # a second Ctrl-C must not break into the clean-up of the first
    with first_sigint_only(restore=argv is not None) as sigint, sigterm_raises():
        code = _main(argv, sigint)
    # a KeyboardInterrupt was swallowed (a weakref callback, a __del__); 143: SIGTERM ended the command, not SIGINT
    if sigint.interrupted and code not in (130, 143):
        click.echo("simspad: interrupted", err=True)
        code = 130
    if sigint.interrupted and argv is None:
        # The program is ending on Ctrl-C: its clean-up has run (temporaries removed, pool workers killed) and the
        # line is printed. The interpreter's own shutdown (joining pool threads, atexit) is skipped: under load a
        # second press landing there ended the process by SIGINT (status −2) after the line, not 130.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    writer = sys.modules.get("simspad.io.recording.writer")
    if writer is not None and writer.hdf5_close_failed():
        # A close failed on a full disk: HDF5 would crash retrying it at exit (SIGSEGV); the temporary file is
        # already deleted and the message printed, so end here.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


#: errno values of an OSError that come from the paths or the disk the user chose, not from a bug.
_USER_ERRNOS = {errno.ENAMETOOLONG, errno.EROFS, errno.EACCES, errno.EPERM, errno.ENOSPC, errno.EDQUOT,
                errno.EFBIG, errno.ENOTDIR, errno.EISDIR, errno.ELOOP, errno.ENOENT}


def _internal_error(exc: BaseException) -> int:
    if _DEBUG:
        raise exc
    click.echo(f"simspad: internal error: {type(exc).__name__}: {exc} (run with --debug for the traceback)",
               err=True)
    return 1


def _main(argv: list[str] | None, sigint=None) -> int:
    """Run the CLI; ``sigint`` (:class:`~simspad.cli.interrupt.SigintState`) is marked when a KeyboardInterrupt ends
    the command, whether or not this process's own handler raised it."""
    try:
        cli.main(args=argv, standalone_mode=False)
    except SimSpadError as exc:
        if _DEBUG:
            raise
        click.echo(f"simspad: error: {exc.format()}", err=True)
        return exc.exit_code
    except click.exceptions.Abort as exc:
        # click turns Ctrl-C (KeyboardInterrupt) into Abort; a declined prompt is an Abort of its own
        if isinstance(exc.__cause__, Terminated):
            click.echo("simspad: terminated", err=True)
            return 143
        interrupted = isinstance(exc.__cause__, KeyboardInterrupt)
        if interrupted and sigint is not None:
            sigint.interrupted = True
        click.echo(f"simspad: {'interrupted' if interrupted else 'aborted'}", err=True)
        return 130
    except click.ClickException as exc:
        exc.show()
        return exc.exit_code
    except Terminated:
        click.echo("simspad: terminated", err=True)
        return 143
    except KeyboardInterrupt:
        if sigint is not None:
            sigint.interrupted = True
        click.echo("simspad: interrupted", err=True)
        return 130
    except OSError as exc:
        if _DEBUG or exc.errno not in _USER_ERRNOS:
            return _internal_error(exc)
        # The system refused a path the user named (too long, read-only, no permission, full disk): their input.
        click.echo(f"simspad: error: {exc.filename or ''}{': ' if exc.filename else ''}{exc.strerror}", err=True)
        return 2
    except RecursionError:
        click.echo("simspad: error: input nested too deeply to read (a malformed or hostile file?)", err=True)
        return 2
    except Exception as exc:  # a bug, not bad input: still one line unless --debug
        if _DEBUG:
            raise
        click.echo(f"simspad: internal error: {type(exc).__name__}: {exc} (run with --debug for the traceback)",
                   err=True)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
