"""``rimcl field``: make, import, inspect and plot flow fields."""

import json

import click

from rimcl.cli.options import (
    COUNT,
    FINITE,
    INDEX,
    NON_NEGATIVE,
    POSITIVE,
    handle_errors,
    overwrite_option,
)
from rimcl.core.atomic import check_not_input
from rimcl.core.errors import RimclError

_output_option = click.option(
    "-o", "--output", type=click.Path(dir_okay=False), required=True, help="Output file."
)
_field_argument = click.argument(
    "field_path", required=False, metavar="[FIELD]", type=click.Path(dir_okay=False)
)


@click.group()
def field():
    """Make, import, inspect and plot flow fields (rimcl field files, HDF5)."""


@field.command()
@click.option(
    "--grid",
    type=click.IntRange(min=16),
    default=64,
    show_default=True,
    help="Points per side N of the 2π box.",
)
@click.option("--seed", type=INDEX, default=0, show_default=True, help="Seed of the initial blobs.")
@click.option(
    "--reynolds",
    type=POSITIVE,
    default=None,
    help="Reynolds number 1/ν (default 400 (N/64)^(4/3): k_max η ≈ 1 at the peak).",
)
@click.option("--frames", type=COUNT, default=3, show_default=True, help="Frames to record.")
@click.option(
    "--dt",
    "--frame-dt",
    type=POSITIVE,
    default=0.005,
    show_default=True,
    help="Time between frames (L0/U0).",
)
@click.option(
    "--gravity",
    type=click.Choice(["x1", "x2", "x3"]),
    default="x3",
    show_default=True,
    help="Gravity points along minus this axis.",
)
@click.option(
    "--start-time",
    type=NON_NEGATIVE,
    default=None,
    help="Record from this time instead of the kinetic-energy peak (short test runs).",
)
@click.option(
    "--gradient/--no-gradient",
    default=True,
    show_default=True,
    help="Store the spectral density gradient (else readers recompute it).",
)
@click.option(
    "--sheet-velocity",
    "sheet_x1",
    type=float,
    default=None,
    metavar="X1",
    help="Store only the in-plane velocity (u2, u3) on the sheet x1 = X1 (small files).",
)
@_output_option
@overwrite_option
@handle_errors
def synth(grid, seed, reynolds, frames, dt, gravity, start_time, gradient, sheet_x1, output,
          overwrite):  # fmt: skip
    """Synthetic buoyancy-driven turbulence (pseudo-spectral Boussinesq solver).

    Two fluids (densities 1 and 1.105, Atwood 0.05, Sc 1) start at rest in random blobs
    in a periodic 2π box; the run goes to the peak of turbulent kinetic energy and then
    writes FRAMES frames DT apart with density, velocity and (by default) the exact
    spectral density gradient.

    \b
      rimcl field synth --grid 32 --seed 1 -o f32.h5        # seconds
      rimcl field synth --grid 64 -o mixing64.h5            # 30-60 s on 2 cores
      rimcl field synth --grid 64 --frames 16 --frame-dt 0.02 --sheet-velocity 0 \\
          --no-gradient -o many.h5                          # density + sheet velocity
    """
    from rimcl.fields.synth import history_table, run_synth

    result = run_synth(
        output,
        overwrite=overwrite,
        grid=grid,
        seed=seed,
        reynolds=reynolds,
        frames=frames,
        frame_dt=dt,
        gravity_axis=gravity,
        t_start=start_time,
        store_gradient=gradient,
        sheet_x1=sheet_x1,
        progress=True,
    )
    click.echo(history_table(result))
    click.echo(f"wrote {output}")


@field.command(name="import")
@click.argument("inputs", nargs=-1, required=True, type=click.Path())  # a Zarr store: a folder
@click.option(
    "--axes",
    default="x,y,z",
    show_default=True,
    help="DNS axes that become x1,x2,x3 (x1 is the depth the camera looks along).",
)
@click.option("--crop", default=None, help="Node ranges along x1,x2,x3, e.g. '0:256,:,0:128'.")
@click.option("--stride", default=None, help="Keep every S-th node: 'S' or 'S1,S2,S3'.")
@click.option(
    "--frames", default=None, help="Time indices tttt to import, e.g. '285-287' (default all)."
)
@click.option(
    "--t0",
    type=FINITE,
    default=0.0,
    show_default=True,
    help="Time of index 1 (when files hold no times).",
)
@click.option(
    "--dt",
    type=POSITIVE,
    default=0.04,
    show_default=True,
    help="Time between indices (JHTDB mixing: 0.04).",
)
@click.option(
    "--boundary",
    type=click.Choice(["auto", "clamp", "periodic"]),
    default="auto",
    show_default=True,
    help="auto: periodic when the grid spans a full --period on every axis.",
)
@click.option(
    "--period",
    type=POSITIVE,
    default=6.283185307179586,
    show_default=True,
    help="Box period (JHTDB: 2π).",
)
@click.option(
    "--gradient",
    type=click.Choice(["auto", "spectral", "fd2", "fd4", "fd6", "none"]),
    default="auto",
    show_default=True,
    help="Density gradient to store (auto: spectral if periodic, else fd4).",
)
@click.option("--title", default=None, help="Title recorded in the file.")
@click.option(
    "--depth-axis",
    default=None,
    help="CF/npz data: the dimension (name or x/y/z) the camera looks along; it becomes x1.",
)
@click.option("--variable", default=None, help="CF/npz data: the scalar's variable name.")
@click.option(
    "--quantity",
    type=click.Choice(["density", "temperature", "salinity", "index", "delta_n"]),
    default=None,
    help="CF/npz data: what the scalar is (default: from its name or standard_name).",
)
@click.option(
    "--units",
    default=None,
    help="CF/npz data: the scalar's units, UDUNITS (K, degC, 'kg m-3', g/kg, ...); needed "
    "where a temperature, salinity or density has no units attribute.",
)
@click.option(
    "--velocity", default=None, help="CF/npz data: velocity variables along x,y,z ('u,v,w')."
)
@click.option(
    "--fluid",
    type=click.Choice(["water", "air", "saltwater"]),
    default="water",
    show_default=True,
    help="Fluid whose n(T) or n(S) turns a temperature or salinity into an index.",
)
@click.option("--wavelength", type=POSITIVE, default=532.0, show_default=True, help="Light (nm).")
@click.option(
    "--base-temperature",
    type=FINITE,
    default=20.0,
    show_default=True,
    help="The fluid's temperature (°C) for a salinity field.",
)
@click.option("--n-ref", type=POSITIVE, default=None, help="Reference index of a delta_n field.")
@_output_option
@overwrite_option
@handle_errors
def import_(inputs, axes, crop, stride, frames, t0, dt, boundary, period, gradient, title,
            depth_axis, variable, quantity, units, velocity, fluid, wavelength,
            base_temperature, n_ref, output, overwrite):  # fmt: skip
    """Import your own flow, or JHTDB cut-outs, as a rimcl field file.

    CF-convention netCDF-4/HDF5 files (Zarr stores where xarray and zarr are installed,
    and .npz files) of a temperature, salinity,
    density, refractive index or delta_n, with their coordinates and velocity u, v, w:
    units from the attributes; --depth-axis names the camera's depth. A temperature or
    salinity becomes the fluid's refractive index (the file then runs "as is", case
    delta_n).

    JHTDB cut-outs: datasets Density_<tttt> / density_<tttt> (and optionally
    Velocity_<tttt>), shaped (nz, ny, nx, ncomp) with 1-D xcoor, ycoor, zcoor; one file
    per time or several times per file. Or one .npz (docs: import a flow field).

    \b
      rimcl field import tank.nc --depth-axis y -o tank.h5
      rimcl field import tank.zarr --depth-axis y -o tank.h5
      rimcl field import mixing_0285.h5 mixing_0286.h5 -o jhtdb.h5
      rimcl field import cutout.nc --axes z,y,x --crop 0:128,:,: --stride 2 -o jhtdb.h5
    """
    from rimcl.fields.cf_import import import_dataset, is_cf_input
    from rimcl.fields.jhtdb import import_flow

    check_not_input(output, inputs)  # an import never replaces what it reads
    cf_options = (depth_axis, variable, quantity, units, velocity, n_ref)
    if any(v is not None for v in cf_options) or is_cf_input(inputs):
        if len(inputs) != 1:
            raise RimclError("import one CF dataset, Zarr store or .npz file at a time")
        written = import_dataset(
            inputs[0],
            output,
            fluid=fluid,
            wavelength_nm=wavelength,
            temperature_c=base_temperature,
            n_ref=n_ref,
            gradient=gradient,
            title=title,
            overwrite=overwrite,
            depth_axis=depth_axis,
            variable=variable,
            quantity=quantity,
            units=units,
            velocity=velocity,
            crop=crop,
            stride=stride,
            frames=frames,
            t0=t0,
            dt=dt,
            boundary=boundary,
            period=period,
        )
        click.echo(f"wrote {written}")
        return
    written = import_flow(
        inputs,
        output,
        axes=axes,
        crop=crop,
        stride=stride,
        frames=frames,
        t0=t0,
        dt=dt,
        boundary=boundary,
        period=period,
        gradient=gradient,
        title=title,
        overwrite=overwrite,
    )
    click.echo(f"wrote {written}")


@field.command()
@_field_argument
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of text.")
@click.option(
    "--values",
    is_flag=True,
    help="Also stream every frame for value ranges, velocity rms and Δn_max per case.",
)
@handle_errors
def info(field_path, as_json, values):
    """Grid, frames, times, storage and memory of a field file (metadata only, at once
    whatever its size); with --values also value ranges and Δn_max per case.

    FIELD defaults to the shipped sample.
    """
    from rimcl.fields.info import describe_field_file, format_description
    from rimcl.fields.sample import sample_path

    described = describe_field_file(field_path or sample_path(), values=values)
    click.echo(json.dumps(described, indent=2) if as_json else format_description(described))


@field.command()
@_field_argument
@click.option("--frame", type=INDEX, default=0, show_default=True, help="Stored frame to show.")
@click.option("--time", type=FINITE, default=None, help="Interpolate to this time instead.")
@click.option(
    "--plane",
    type=click.Choice(["x2x3", "x1x2", "x1x3"]),
    default="x2x3",
    show_default=True,
    help="Slice plane (x2x3 is parallel to the light sheet).",
)
@click.option(
    "--at", type=FINITE, default=None, help="Plane position along its normal (default: middle)."
)
@click.option(
    "--quantity",
    type=click.Choice(["all", "density", "gradient", "velocity"]),
    default="all",
    show_default=True,
    help="What to draw.",
)
@click.option("--case", default=None, help="Gladstone–Dale case C0..C4: show δn and |∇n|.")
@click.option(
    "--k-rho", type=NON_NEGATIVE, default=None, help="Custom Gladstone–Dale product G = Kρ."
)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False),
    default="field.png",
    show_default=True,
    help="PNG or PDF file.",
)
@overwrite_option
@handle_errors
def show(field_path, frame, time, plane, at, quantity, case, k_rho, output, overwrite):
    """Draw a slice of a field file: density (or δn), |∇ρ| (or |∇n|), velocity.

    FIELD defaults to the shipped sample.

    \b
      rimcl field show -o sample.png
      rimcl field show jhtdb.h5 --case C1 --plane x1x2 -o jhtdb.png
    """
    from rimcl.fields.plot import save_figure, slice_figure
    from rimcl.fields.sample import sample_path

    path = field_path or sample_path()
    check_not_input(output, [path])
    options = dict(frame=frame, time=time, plane=plane, at=at, quantity=quantity, case=case,
                   k_rho=k_rho)  # fmt: skip
    figure = slice_figure(path, **options)
    save_figure(figure, output, config={"field": str(path), **options}, overwrite=overwrite)
    click.echo(f"wrote {output}")
