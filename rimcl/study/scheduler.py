"""Which Dask scheduler a study uses, checked before anything is written.

``run.scheduler`` / ``--scheduler``: ``local:N`` (N worker processes here, at most the
usable cores) or the address of a running scheduler, which must answer Dask's handshake
within :data:`PROBE_SECONDS` (:func:`probe_scheduler`); :mod:`rimcl.study.distributed`
connects and measures.
"""

import os
import re
import socket
import time
from urllib.parse import urlsplit

from rimcl.core.errors import RimclError

INSTALL_HINT = 'pip install "rimcl[distributed]"'
#: Seconds a scheduler address has to accept a connection and send Dask's handshake.
PROBE_SECONDS = 5.0
#: Dask's default scheduler port, for an address without one.
DEFAULT_PORT = 8786


def parse_scheduler(spec):
    """What a scheduler spec asks for.

    Parameters
    ----------
    spec : str
        ``"local:N"`` (N worker processes on this machine) or the address of a running
        Dask scheduler (``"tcp://HOST:PORT"``, any ``scheme://`` Dask accepts).

    Returns
    -------
    ("local", int) or ("address", str)
    """
    text = str(spec).strip()
    local = re.fullmatch(r"local:(\d+)", text)
    if local and int(local.group(1)) >= 1:
        return "local", int(local.group(1))
    if re.fullmatch(r"[a-z]+://\S+", text):
        return "address", text
    raise RimclError(
        f"scheduler {spec!r} (run.scheduler, --scheduler) must be local:N with N >= 1 "
        "or a Dask scheduler address such as tcp://HOST:8786"
    )


def usable_cores():
    """CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        return os.cpu_count() or 1


def _printable(data, limit=40):
    text = data[:limit].decode("latin-1")
    return "".join(c if c.isprintable() else "." for c in text)


def probe_scheduler(address, timeout=PROBE_SECONDS):
    """Check that a Dask scheduler answers at ``address``, within ``timeout`` seconds.

    A Dask scheduler sends its handshake (a msgpack map naming its Python and pickle
    protocol) as soon as it accepts a TCP connection; Dask's client waits for it without
    a limit, so a listener that says nothing (an HTTP server, a stopped process) would
    hang the study. Addresses of other schemes than ``tcp://`` (``tls://`` needs the
    certificates; ``ucx://``, ``ws://``...) are only checked for a listening port where
    they have one.

    Parameters
    ----------
    address : str
        ``scheme://HOST[:PORT]`` (port default :data:`DEFAULT_PORT`).
    timeout : float
        Seconds to connect, and again to receive the handshake.

    Returns
    -------
    str
        What answered, for the log ("a Dask scheduler (Python 3.11.7)").

    Raises
    ------
    RimclError
        Nothing listens, no machine answers, or something that is not a Dask scheduler.
    """
    parts = urlsplit(address)
    try:
        host, port = parts.hostname, parts.port or DEFAULT_PORT
    except ValueError:
        raise RimclError(f"scheduler address {address!r} has no valid port") from None
    if parts.scheme not in ("tcp", "tls") or not host:
        return f"a {parts.scheme}:// address (not checked before connecting)"
    where = f"the Dask scheduler address {address}"
    try:
        connection = socket.create_connection((host, port), timeout=timeout)
    except socket.gaierror as exc:
        raise RimclError(f"cannot resolve host {host!r} of {where} ({exc.strerror})") from None
    except ConnectionRefusedError:
        raise RimclError(f"nothing listens at {where} (connection refused)") from None
    except TimeoutError:
        raise RimclError(
            f"no answer from {where} within {timeout:g} s (no such machine, or a firewall)"
        ) from None
    except OSError as exc:
        raise RimclError(f"cannot reach {where}: {exc.strerror or exc}") from None
    with connection:
        if parts.scheme == "tls":
            return "a listening port (TLS: the handshake is Dask's)"
        received = b""
        deadline = time.monotonic() + timeout
        try:
            # Dask's TCP frames: 8 bytes of total length, 8 of frame count, 8 per frame size
            while len(received) < 16 or len(received) < 8 + int.from_bytes(received[:8], "little"):
                left = deadline - time.monotonic()
                if left <= 0 or len(received) > 1 << 16:
                    break
                connection.settimeout(left)
                chunk = connection.recv(4096)
                if not chunk:
                    break
                received += chunk
        except TimeoutError:
            pass
        except OSError as exc:
            raise RimclError(f"{where} dropped the connection: {exc.strerror or exc}") from None
    if not received:
        raise RimclError(
            f"{where} accepted the connection but sent nothing within {timeout:g} s: not a "
            "Dask scheduler (an HTTP server or another service?)"
        )
    if b"pickle-protocol" not in received:
        raise RimclError(
            f"{where} answered {_printable(received)!r}: not a Dask scheduler's handshake"
        )
    return "a Dask scheduler" + _handshake_python(received)


def _handshake_python(received):
    """ " (Python X.Y.Z)" from a Dask handshake's bytes, "" where it cannot be read."""
    try:
        import msgpack

        count = int.from_bytes(received[8:16], "little")
        start = 16 + 8 * count
        info = msgpack.unpackb(received[start:], strict_map_key=False)
        return " (Python " + ".".join(str(part) for part in info["python"]) + ")"
    except Exception:  # an older or newer Dask frames its handshake otherwise: no version
        return ""


def check_scheduler(spec):
    """Refuse, before anything is written, a scheduler the study cannot use.

    ``local:N`` above the cores this process may use is refused (each worker measures
    on one core; more only compete for them); an address must answer as a Dask
    scheduler within :data:`PROBE_SECONDS` (:func:`probe_scheduler`).

    Parameters
    ----------
    spec : str
        See :func:`parse_scheduler`.

    Returns
    -------
    str
        One line saying what will measure.
    """
    kind, value = parse_scheduler(spec)
    _import_distributed(spec)
    if kind == "local":
        cores = usable_cores()
        if value > cores:
            raise RimclError(
                f"scheduler local:{value} asks for {value} worker processes, but this "
                f"machine gives rimcl {cores} core(s): use local:{cores} or fewer"
            )
        return f"{value} local worker processes"
    return f"scheduler {value}: {probe_scheduler(value, timeout=PROBE_SECONDS)} answered"


def _import_distributed(spec):
    try:
        import distributed
    except ImportError:
        raise RimclError(
            f"scheduler {spec!r} needs Dask distributed, which is not installed: {INSTALL_HINT}"
        ) from None
    return distributed
