"""The shipped sample's flow with its full velocity, generated once and cached.

The shipped sample (:func:`rimcl.fields.sample.sample_path`) stores the velocity only on its
sheet plane ``x1 = 0``, to stay small. A light sheet elsewhere in the depth needs the
velocity there: :func:`full_velocity_sample` runs the built-in solver
(:mod:`rimcl.fields.synth`, ``rimcl field synth``) once with the sample's own recorded
settings and full velocity, and keeps the file in the user's cache directory
(``platformdirs.user_cache_dir("rimcl")``, or ``$RIMCL_CACHE_DIR``). The file is written
atomically, carries the provenance of every synth file (settings, versions), and is reused
while its recorded settings match.
"""

import hashlib
import json
import os
from pathlib import Path

import h5py

#: Environment variable naming the cache directory (default: the user's cache directory).
CACHE_ENV = "RIMCL_CACHE_DIR"
#: Settings of :func:`rimcl.fields.synth.synthesize` a cached file must record to be reused.
_KEYS = ("grid", "seed", "reynolds", "schmidt", "frames", "frame_dt", "gravity_axis")


def cache_dir():
    """The directory of rimcl's cached files (``$RIMCL_CACHE_DIR``, else the user's cache
    directory for rimcl)."""
    given = os.environ.get(CACHE_ENV)
    if given:
        return Path(given)
    from platformdirs import user_cache_dir

    return Path(user_cache_dir("rimcl"))


def sample_settings():
    """The solver settings that made the shipped sample (from its recorded ``config``).

    Returns
    -------
    dict
        Keyword arguments of :func:`rimcl.fields.synth.synthesize`; ``sheet_x1`` None (full
        velocity) and no stored gradient, as the sample.
    """
    from rimcl.fields.sample import sample_path

    with h5py.File(sample_path(), "r") as h5:
        config = json.loads(h5.attrs["config"])
    return {key: config[key] for key in _KEYS}


def _reusable(path, settings):
    """Whether ``path`` is a complete full-velocity synth file made with ``settings``."""
    try:
        with h5py.File(path, "r") as h5:
            config = json.loads(h5.attrs["config"])
            full = config.get("velocity_stored") == "full"
    except (OSError, KeyError, ValueError):
        return False
    return full and all(config.get(key) == value for key, value in settings.items())


def full_velocity_sample(settings=None, report=None):
    """A field file of the built-in flow with full velocity, generated once and cached.

    Parameters
    ----------
    settings : dict, optional
        Solver settings (:data:`_KEYS`); default :func:`sample_settings`, the shipped
        sample's own flow.
    report : callable, optional
        Called with one line when the file is generated (not when it is reused).

    Returns
    -------
    pathlib.Path
    """
    from rimcl.fields.synth import run_synth

    settings = sample_settings() if settings is None else dict(settings)
    digest = hashlib.sha256(json.dumps(settings, sort_keys=True).encode()).hexdigest()[:12]
    path = cache_dir() / f"flow{settings['grid']}-full-velocity-{digest}.h5"
    if _reusable(path, settings):
        return path
    if report is not None:
        report(
            f"the built-in flow stores its velocity only on x1 = 0: generating it once with "
            f"full velocity ({settings['grid']}³, rimcl field synth) into {path}"
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    run_synth(path, overwrite=True, store_gradient=False, sheet_x1=None, **settings)
    return path
