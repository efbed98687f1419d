"""Options and error handling shared by the ``rimcl`` subcommands."""

import functools

import click

from rimcl.errors import RimclError

device_option = click.option(
    "--device",
    "device_spec",
    default=None,
    metavar="SPEC",
    help="OpenCL device: 'pocl', 'nvidia', 'P:D' from 'rimcl devices' "
    "(default: $RIMCL_DEVICE, then a GPU, then a CPU).",
)
field_option = click.option(
    "--field",
    "field_path",
    type=click.Path(dir_okay=False),
    default=None,
    help="rimcl field file (default: the shipped sample).",
)
case_option = click.option(
    "--case", default=None, help="Gladstone–Dale case C0..C4 (default C1, air)."
)
k_rho_option = click.option(
    "--k-rho", type=float, default=None, help="Custom Gladstone–Dale product G = Kρ."
)
seed_option = click.option(
    "--seed", type=int, default=0, show_default=True, help="Random seed (tracers, rays)."
)
overwrite_option = click.option(
    "--overwrite", is_flag=True, help="Replace an existing output file."
)
interp_option = click.option(
    "--interp",
    type=click.Choice(["trilinear", "texture", "bspline3", "auto"]),
    default="trilinear",
    show_default=True,
    help="Interpolation of the gridded field.",
)
precision_option = click.option(
    "--precision",
    type=click.Choice(["f32", "f32c", "f64"]),
    default="f32c",
    show_default=True,
    help="Accumulation precision: plain float32, compensated float32, float64.",
)
step_option = click.option(
    "--step",
    default=None,
    metavar="DT|auto|adaptive",
    help="Integration step in t (dt = ds/n); default half a cell of arc; 'auto' calibrates "
    "a fixed step, 'adaptive' sizes each step by step doubling (see --tolerance).",
)
tolerance_option = click.option(
    "--tolerance",
    type=float,
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
    if not step > 0:
        raise click.BadParameter("the step must be positive", param_hint="--step")
    return step


def case_or_default(case, k_rho):
    """The case to use when neither ``--case`` nor ``--k-rho`` is given: C1 (air)."""
    return "C1" if case is None and k_rho is None else case


def handle_errors(func):
    """Turn library errors into one clear line and exit status 1 (tracebacks with -v)."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        ctx = click.get_current_context()
        verbose = bool((ctx.find_root().obj or {}).get("verbose"))
        try:
            return func(*args, **kwargs)
        except (click.ClickException, click.exceptions.Exit, click.Abort):
            raise
        except RimclError as exc:
            if verbose:
                raise
            raise click.ClickException(str(exc)) from None
        except (OSError, ValueError) as exc:
            if verbose:
                raise
            raise click.ClickException(f"{type(exc).__name__}: {exc}") from None

    return wrapper
