"""The one loader of OpenCL programs: kernel sources are package resources of
``rimcl.kernels``; headers are found by the compiler through ``-I``, so build errors
name the real file and line. Built programs and their kernels are cached per context
and define set.
"""

import functools
from importlib import resources

from rimcl.core.errors import RimclError


def kernel_dir():
    """Directory holding the installed ``.cl`` and ``.h`` files."""
    return resources.files("rimcl.kernels")


def kernel_files():
    """Names of all ``.cl`` program files shipped with rimcl."""
    return sorted(p.name for p in kernel_dir().iterdir() if p.name.endswith(".cl"))


def _define_options(defines):
    options = []
    for name, value in sorted(defines.items()):
        options.append(f"-D{name}" if value is None else f"-D{name}={value}")
    return options


@functools.lru_cache(maxsize=64)
def _build(context, filename, define_items, extra_options):
    import pyopencl as cl

    path = kernel_dir() / filename
    if not path.is_file():
        raise RimclError(f"kernel file {filename} is not installed")
    source = f'#include "{filename}"\n'
    options = [f"-I{kernel_dir()}", *_define_options(dict(define_items)), *extra_options]
    try:
        return cl.Program(context, source).build(options=options)
    except cl.Error as exc:
        # one line: the compiler's first error (the whole log with rimcl -v)
        first = next(
            (line.strip() for line in str(exc).splitlines() if "error:" in line.lower()),
            str(exc).splitlines()[0] if str(exc) else type(exc).__name__,
        )
        device = context.devices[0].name.strip()
        raise RimclError(
            f"OpenCL build of {filename} failed on {device}: {first}; another device "
            "(--device, see 'rimcl devices') or the distribution's PoCL may build it"
        ) from exc


def build_program(context, filename, defines=None, options=()):
    """Build (or fetch from the cache) ``filename`` with ``-D`` defines.

    Parameters
    ----------
    context : pyopencl.Context
    filename : str
        A ``.cl`` file of ``rimcl.kernels``.
    defines : dict of str to (str, int, float or None), optional
        ``{"NAME": value}`` becomes ``-DNAME=value``; ``None`` gives ``-DNAME``.
    options : sequence of str
        Further compiler options.

    Returns
    -------
    pyopencl.Program
    """
    items = tuple(sorted((defines or {}).items()))
    return _build(context, filename, items, tuple(options))


@functools.lru_cache(maxsize=256)
def get_kernel(program, name):
    """Fetch a kernel object once per program (``cl.Kernel`` is not free)."""
    import pyopencl as cl

    try:
        return cl.Kernel(program, name)
    except cl.Error as exc:  # INVALID_KERNEL_NAME from a build that lost the kernel
        device = program.devices[0].name.strip()
        raise RimclError(
            f"OpenCL kernel {name} cannot be created on {device} ({exc}); another device "
            "(--device, see 'rimcl devices') or the distribution's PoCL may build it"
        ) from exc
