"""Scene keys of the physics beyond ray optics: sensor noise, Mie scattering, the fluid.

The sections ``[sensor]`` (photon, read and background noise), ``[mie]`` (the tracers'
scattering weights) and ``[fluid]`` (the fluid of ``dT=``/``dS=`` cases).
"""

from rimcl.scene.key import SceneKey


def physics_keys():
    """The keys of the sensor, the tracers' Mie scattering and the fluid."""
    return (
        SceneKey(
            "sensor",
            "noise",
            True,
            "bool",
            "photon shot noise, read noise and background (false: the deterministic camera)",
        ),
        SceneKey(
            "sensor",
            "peak_electrons",
            10000.0,
            "float",
            "mean photoelectrons at the peak of a tracer's reference image",
            positive=True,
        ),
        SceneKey("sensor", "read_noise_e", 2.0, "float", "read noise (e- rms)", minimum=0.0),
        SceneKey("sensor", "background_e", 20.0, "float", "background per pixel (e-)", minimum=0.0),
        SceneKey("sensor", "full_well_e", 30000.0, "float", "full well (e-)", positive=True),
        SceneKey(
            "sensor",
            "gain_e_per_count",
            None,
            "float",
            "e- per count; default: full well / (2**bit_depth - 1)",
            positive=True,
            example=7.3,
        ),
        SceneKey(
            "sensor",
            "seed",
            None,
            "int",
            "seed of the noise draws; default tracers.seed",
            minimum=0,
            example=0,
        ),
        SceneKey("mie", "enabled", True, "bool", "weight each ray by its Mie scattering intensity"),
        SceneKey("mie", "diameter_um", 10.0, "float", "particle diameter (µm)", positive=True),
        SceneKey(
            "mie",
            "particle_index",
            1.59,
            "float",
            "particle index (1.59 polystyrene, 1.45 DEHS)",
            minimum=1.0,
        ),
        SceneKey("mie", "particle_absorption", 0.0, "float", "imaginary part of it", minimum=0.0),
        SceneKey(
            "mie",
            "fluid_index",
            None,
            "float",
            "index around the particle; default: the measured case's mean index",
            minimum=1.0,
            example=1.335,
        ),
        SceneKey("mie", "wavelength_nm", 532.0, "float", "vacuum wavelength (nm)", positive=True),
        SceneKey(
            "mie",
            "sheet_direction",
            [0.0, 1.0, 0.0],
            "vector",
            "propagation direction of the light sheet (x1, x2, x3)",
        ),
        SceneKey(
            "mie",
            "polarisation",
            "linear",
            "str",
            "relative to each ray's scattering plane, or linear along polarisation_direction",
            choices=("unpolarised", "perpendicular", "parallel", "linear"),
        ),
        SceneKey(
            "mie",
            "polarisation_direction",
            [0.0, 0.0, 1.0],
            "vector",
            "the linear polarisation (perpendicular to the sheet direction)",
        ),
        SceneKey(
            "fluid",
            "kind",
            "",
            "str",
            'the fluid of dT=/dS= cases: water, air or saltwater ("": none)',
            choices=("", "water", "air", "saltwater"),
        ),
        SceneKey("fluid", "temperature_c", 20.0, "float", "base temperature (°C)"),
        SceneKey(
            "fluid", "salinity_g_kg", 0.0, "float", "base salinity (g/kg; saltwater)", minimum=0.0
        ),
        SceneKey("fluid", "pressure_pa", 101325.0, "float", "pressure (Pa; air)", positive=True),
        SceneKey(
            "fluid", "relative_humidity", 0.0, "float", "relative humidity 0..1 (air)", minimum=0.0
        ),
        SceneKey("fluid", "wavelength_nm", 532.0, "float", "vacuum wavelength (nm)", positive=True),
        SceneKey(
            "fluid",
            "light_density",
            None,
            "float",
            "the field's light fluid (dimensionless density): the warm or fresh one; "
            "default: the field file's rho_light, else 1.0",
            positive=True,
            example=1.0,
        ),
        SceneKey(
            "fluid",
            "heavy_density",
            None,
            "float",
            "the field's heavy fluid: the cold or salty one; default: the field file's "
            "rho_heavy, else 1.105",
            positive=True,
            example=1.105,
        ),
    )
