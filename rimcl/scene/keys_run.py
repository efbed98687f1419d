"""Scene keys of how a study runs and of its PIV frames.

The sections ``[run]`` (device, engine, mode, Dask scheduler and batching) and ``[piv]``
(frames, light sheet and correlation).
"""

from rimcl.scene.key import SceneKey, choices


def run_keys():
    """The keys of the ``[run]`` section: devices, engines, mode and scheduling."""
    choice = choices()
    return (
        SceneKey(
            "run",
            "device",
            "",
            "str",
            'OpenCL device (see "rimcl devices"); "" = $RIMCL_DEVICE, then a GPU, then a CPU',
        ),
        SceneKey(
            "run",
            "engine",
            "device",
            "str",
            "where tracer images are rendered and located: device (rays, images and "
            "centroids on the OpenCL device; needs fp64) or numpy (the readable reference "
            "engine, tracer by tracer)",
            choices=choice["engine"],
        ),
        SceneKey(
            "run",
            "numerics",
            True,
            "bool",
            "with the figures, the paper's Appendix A check: one case (C1) at a half and a "
            "quarter of the step and on every second and fourth grid node, its |ε_x| PDFs "
            "and Richardson's estimate of a finer step and grid in figures/numerics.png",
        ),
        SceneKey(
            "run",
            "sensitivity",
            False,
            "bool",
            "measure every case again with the other interpolation and 4 times the rays "
            "(2 studies more): their part of the sensitivity band of each headline number "
            "in summary.md (without it the band holds the threshold halved and doubled, "
            "located in the same images, and the excluded tracers counted by their optics "
            "error)",
        ),
        SceneKey(
            "run",
            "ray_sample",
            20000,
            "int",
            "first-frame rays kept per case for the ray diagnostics",
            minimum=0,
        ),
        SceneKey(
            "run",
            "rays_per_batch",
            131072,
            "int",
            "rays traced per batch (bounds the memory)",
            positive=True,
        ),
        SceneKey(
            "run",
            "mode",
            "ptv",
            "str",
            "ptv: tracer tracks; piv: cross-correlation of full frames ([piv]); both: each "
            "case both ways, compared in summary.md; lpt: 3-D tracking with several cameras "
            "([rig], [illumination], [lpt])",
            choices=("ptv", "piv", "both", "lpt"),
        ),
        SceneKey(
            "run",
            "scheduler",
            "",
            "str",
            'Dask scheduler measuring the cases: "" = this process; "local:N" = N worker '
            'processes here; "tcp://HOST:PORT" = a running scheduler (rimcl[distributed])',
        ),
        SceneKey(
            "run",
            "shard_tracers",
            100,
            "int",
            "tracers per Dask task (one case, one shard of tracers) with run.scheduler; "
            "the results do not depend on it",
            positive=True,
        ),
    )


def piv_keys():
    """The ``[piv]`` section (:mod:`rimcl.piv.render`, :mod:`rimcl.piv.analysis`).

    Frames, light sheet and correlation.
    """
    return (
        SceneKey(
            "piv",
            "pixels",
            512,
            "int",
            "pixels across the field of view of the PIV frames (a lens camera: its sensor)",
            positive=True,
        ),
        SceneKey(
            "piv",
            "density",
            0.03,
            "float",
            "particle image density: tracers per pixel inside the sheet's 1/e² thickness",
            positive=True,
        ),
        SceneKey(
            "piv",
            "diameter",
            3.0,
            "float",
            "particle image diameter d = 4 σ (pixels; a lens camera: its own tracer image); at "
            "least 1 (no lens images a particle smaller than a pixel; below 2 px peak locking)",
            minimum=1.0,
        ),
        SceneKey(
            "piv",
            "sheet_thickness",
            None,
            "float",
            "light-sheet thickness between the 1/e² points of its Gaussian profile along x1 "
            "(field length units); default 8 pixels",
            positive=True,
            example=0.1,
        ),
        SceneKey(
            "piv", "bit_depth", 16, "int", "bits per pixel of the PIV frames (8 to 16)", minimum=8
        ),
        SceneKey(
            "piv",
            "rays",
            64,
            "int",
            "rays per tracer of the PIV frames, with the camera's kind and optics (a plane "
            "camera: a fan of round(sqrt(rays)) per side)",
            positive=True,
        ),
        SceneKey(
            "piv",
            "dt",
            0.1,
            "float",
            "time between exposures A and B; 0.1 on the sample moves tracers 1.5 px rms, "
            "up to 4.5 px, at 512 px",
            positive=True,
        ),
        SceneKey(
            "piv",
            "window",
            32,
            "int",
            "interrogation window of the last pass (px, even)",
            positive=True,
        ),
        SceneKey("piv", "overlap", 0.5, "float", "overlap of neighbouring windows", minimum=0.0),
        SceneKey(
            "piv",
            "passes",
            3,
            "int",
            "correlation passes (2 and more deform the windows)",
            positive=True,
        ),
    )
