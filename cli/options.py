"""Options and error handling shared by the ``rimcl`` subcommands."""

import errno
import functools
import math

import click

from rimcl.core.errors import RimclError, first_line

#: Longest error line printed (a message quoting a huge value is cut).
_LONGEST_MESSAGE = 400
#: Largest step count the kernels take (a signed 32-bit counter).
MAX_STEPS_LIMIT = 2**31 - 1


class FiniteFloat(click.ParamType):
    """A finite number, optionally bounded below (inclusive or not) and above.

    Parameters
    ----------
    minimum, maximum : float, optional
    open_minimum : bool
        Refuse ``minimum`` itself (``positive`` numbers: ``minimum=0, open_minimum=True``).
    """

    name = "float"

    def __init__(self, minimum=None, maximum=None, open_minimum=False):
        self.minimum, self.maximum, self.open_minimum = minimum, maximum, open_minimum

    def convert(self, value, param, ctx):
        try:
            number = float(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not a number", param, ctx)
        if not math.isfinite(number):
            self.fail(f"must be a finite number, got {value!r}", param, ctx)
        low = self.minimum
        if low is not None and (number < low or (self.open_minimum and number == low)):
            bound = ">" if self.open_minimum else ">="
            self.fail(f"must be {bound} {low:g}, got {value}", param, ctx)
        if self.maximum is not None and number > self.maximum:
            self.fail(f"must be <= {self.maximum:g}, got {value}", param, ctx)
        return number


#: A finite number > 0 (lengths, times, σ, Reynolds numbers).
POSITIVE = FiniteFloat(0.0, open_minimum=True)
#: A finite number >= 0.
NON_NEGATIVE = FiniteFloat(0.0)
#: Any finite number.
FINITE = FiniteFloat()
#: A count of at least one (tracers, rays, pixels, frames).
COUNT = click.IntRange(min=1)
#: A seed or an index: an integer >= 0.
INDEX = click.IntRange(min=0)

device_option = click.option(
    "--device",
    "device_spec",
    default=None,
    metavar="SPEC",
    help="OpenCL device: 'pocl', 'nvidia', 'P:D' from 'rimcl devices' "
    "(default: $RIMCL_DEVICE, then a GPU, then a CPU).",
)
engine_option = click.option(
    "--engine",
    type=click.Choice(["device", "numpy"]),
    default=None,
    help="Where tracer images are rendered and located: device (OpenCL, with the trace; "
    "the default) or numpy (the readable reference) [run.engine].",
)
field_option = click.option(
    "--field",
    "field_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="rimcl field file (default: the shipped sample).",
)
case_option = click.option(
    "--case",
    default=None,
    help="The case: C0..C4, G=<value>, dT=<K>, dS=<g/kg> [default: the scene's first case "
    "other than C0, C1 (air) in the default scene].",
)
k_rho_option = click.option(
    "--k-rho", type=NON_NEGATIVE, default=None, help="Custom Gladstone–Dale product G = Kρ."
)
overwrite_option = click.option(
    "--overwrite", is_flag=True, help="Replace an existing output file."
)
step_option = click.option(
    "--step",
    default=None,
    metavar="DT|auto|adaptive",
    help="Integration step in t (dt = ds/n); default half a cell of arc; 'auto' calibrates "
    "a fixed step, 'adaptive' sizes each step by step doubling (see --tolerance).",
)


class _FixedStep(FiniteFloat):
    """A fixed integration step (> 0); ``auto`` and ``adaptive`` are named as trace-only."""

    def convert(self, value, param, ctx):
        if value in ("auto", "adaptive"):
            self.fail(
                f"{value!r} calibrates the step of one trace (rimcl trace --step {value}); a "
                "measurement takes a fixed step, the same in every frame and its reference "
                "(default: half a cell)",
                param,
                ctx,
            )
        return super().convert(value, param, ctx)


#: ``--step`` of the commands that measure (render, piv render/sequence, study): a number.
measure_step_option = click.option(
    "--step",
    type=_FixedStep(0.0, open_minimum=True),
    default=None,
    metavar="DT",
    help="Integration step in t (dt = ds/n) [integrator.step; default half a cell of arc]. "
    "auto/adaptive: rimcl trace.",
)
tolerance_option = click.option(
    "--tolerance",
    type=POSITIVE,
    default=None,
    metavar="LENGTH",
    help="Allowed error of the image points r' for --step adaptive/auto and --interp auto "
    "(field length units; default 0.01 pixel of the paper's 8192-pixel camera).",
)


def parse_step(value):
    """``None``, ``"auto"``, ``"adaptive"`` or a positive float from a ``--step`` value."""
    if value is None or value in ("auto", "adaptive"):
        return value
    try:
        step = float(value)
    except ValueError:
        raise click.BadParameter(
            f"{value!r} is not a number, 'auto' or 'adaptive'", param_hint="--step"
        ) from None
    if not (step > 0 and math.isfinite(step)):
        raise click.BadParameter(
            f"the step must be a positive finite number, got {value!r}", param_hint="--step"
        )
    return step


def _disk_full(exc):
    return isinstance(exc, OSError) and (
        exc.errno == errno.ENOSPC or "No space left on device" in str(exc)
    )


def describe_failure(exc):
    """One line a user can act on, for any exception a command raised.

    :class:`RimclError` carries its own words; memory and disk-full errors are named as
    such; other operating-system errors give their reason and file; anything else is
    named by its type (with -v the traceback is shown instead).

    Returns
    -------
    str
        A single line (newlines folded, cut at a few hundred characters).
    """
    if isinstance(exc, RimclError):
        text = str(exc)
    elif isinstance(exc, MemoryError):
        detail = str(exc) or "an allocation failed"
        text = f"out of memory ({detail}); ask for a smaller grid, fewer tracers or fewer rays"
    elif _disk_full(exc):
        where = f" writing {exc.filename}" if getattr(exc, "filename", None) else ""
        text = f"the disk is full (no space left on device{where}); free space and run again"
    elif isinstance(exc, OSError) and exc.strerror:
        text = exc.strerror + (f": {exc.filename}" if exc.filename else "")
    else:
        text = f"{type(exc).__name__}: {first_line(exc)} (rimcl -v shows where)"
    text = " ".join(text.split())
    if len(text) > _LONGEST_MESSAGE:
        text = text[: _LONGEST_MESSAGE - 1] + "…"
    return text


def run_reporting_errors(ctx, call):
    """Run ``call()``; turn any failure into one line and exit status 1 (tracebacks with
    ``rimcl -v``). Click's own exceptions (usage errors: status 2) pass through."""
    try:
        return call()
    except (click.ClickException, click.exceptions.Exit, click.Abort):
        raise
    except Exception as exc:
        if bool((ctx.find_root().obj or {}).get("verbose")):
            raise
        raise click.ClickException(describe_failure(exc)) from None


def handle_errors(func):
    """Turn every failure of a command into one clear line and exit status 1."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        return run_reporting_errors(click.get_current_context(), lambda: func(*args, **kwargs))

    return wrapper


def _print_default_scene(ctx, _param, value):
    if not value or ctx.resilient_parsing:
        return
    from rimcl.scene.load import default_scene_text

    click.echo(default_scene_text(), nl=False)
    ctx.exit()


def scene_options(func):
    """``SCENE_FILE`` (or ``--scene``) and ``--print-default-scene``: every command that
    measures starts from the same scene (:mod:`rimcl.scene.keys`); its options override
    the scene's keys."""
    func = click.option(
        "--print-default-scene",
        is_flag=True,
        is_eager=True,
        expose_value=False,
        callback=_print_default_scene,
        help="Print the default scene (every key, documented; the same for every command) "
        "and exit.",
    )(func)
    func = click.option(
        "--scene",
        "scene_option",
        type=click.Path(dir_okay=False),
        default=None,
        help="Scene file (TOML), the same as SCENE_FILE.",
    )(func)
    return click.argument("scene_file", required=False, type=click.Path(dir_okay=False))(func)


def command_scene(scene_file, scene_option, overrides, command, preset=None, velocity=True):
    """The checked scene of a command: its scene file (or the default scene) with the
    command's options on top (``{"section.key": value}``; None: not given).

    ``command``: its tag in :data:`rimcl.scene.usage.COMMANDS`; keys set that it does not
    use are refused, or named in one note line (:func:`rimcl.scene.usage.check_use`).

    ``velocity``: the command moves tracers, so a sheet moved inside the shipped sample
    runs on its flow with full velocity (:func:`rimcl.scene.command.place_sheet`, said in
    one line when it is generated)."""
    from pathlib import Path

    from rimcl.scene.command import place_sheet
    from rimcl.scene.load import load_scene

    if scene_file and scene_option and Path(scene_file).resolve() != Path(scene_option).resolve():
        raise click.UsageError("give one scene file: SCENE_FILE or --scene, not both")
    overrides = dict(overrides)
    field_path = overrides.get("field.path")
    if field_path:
        # a field named on the command line is relative to where the command runs
        overrides["field.path"] = str(Path(field_path).resolve())
    scene = load_scene(
        scene_file or scene_option, overrides, preset=preset, command=command, report=click.echo
    )
    return place_sheet(scene, report=click.echo) if velocity else scene
