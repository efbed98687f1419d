"""Dask addresses are checked before work starts (issue 20, item 4): a listener that is
not a Dask scheduler is refused after the probe's own timeout, local:N is capped at the cores, every
mode validates the same way, and local workers leave Ctrl-C to the client."""

import faulthandler
import signal
import socket
import threading
import time

import pytest
from click.testing import CliRunner

from rimcl.cli.main import cli
from rimcl.core.errors import RimclError
from rimcl.study import distributed as dist
from rimcl.study import scheduler as sched

pytest.importorskip("distributed")

#: A probe that has not returned by then hangs: the run is aborted with its tracebacks.
HANG_SECONDS = 120


@pytest.fixture
def silent_listener():
    """A socket that accepts connections (the kernel's backlog does) and says nothing."""
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(8)
        yield f"tcp://127.0.0.1:{server.getsockname()[1]}"


@pytest.fixture
def chatty_listener():
    """A listener that greets every connection like an SSH server."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)

    def serve():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            with conn:
                conn.sendall(b"SSH-2.0-OpenSSH_9.2\r\n")
                time.sleep(0.2)

    threading.Thread(target=serve, daemon=True).start()
    yield f"tcp://127.0.0.1:{server.getsockname()[1]}"
    server.close()


@pytest.fixture
def hang_guard():
    """A hang aborts the run with every thread's traceback (no assertion on time)."""
    faulthandler.dump_traceback_later(HANG_SECONDS, exit=True)
    yield
    faulthandler.cancel_dump_traceback_later()


def test_a_silent_listener_is_refused_after_the_probe_timeout(silent_listener, hang_guard):
    # the probe gives up after its own timeout and says so: the message names that timeout
    with pytest.raises(RimclError, match="accepted the connection but sent nothing within 1 s"):
        sched.probe_scheduler(silent_listener, timeout=1.0)


def test_a_listener_that_is_not_dask_is_named(chatty_listener):
    with pytest.raises(RimclError, match=r"answered 'SSH-2\.0-OpenSSH_9\.2\.\.': not a Dask"):
        sched.probe_scheduler(chatty_listener, timeout=2.0)


def test_nothing_listening_is_refused():
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    with pytest.raises(RimclError, match=r"nothing listens .* \(connection refused\)"):
        sched.probe_scheduler(f"tcp://127.0.0.1:{port}", timeout=2.0)
    with pytest.raises(RimclError, match="cannot resolve host"):
        sched.probe_scheduler("tcp://no-such-host.invalid:8786", timeout=2.0)


def test_a_real_scheduler_answers():
    import distributed

    with distributed.LocalCluster(
        n_workers=0, processes=False, protocol="tcp", host="127.0.0.1", dashboard_address=":0"
    ) as cluster:
        answer = sched.probe_scheduler(cluster.scheduler_address, timeout=5.0)
    assert answer.startswith("a Dask scheduler (Python 3.")


def test_local_workers_are_capped_at_the_cores(monkeypatch):
    monkeypatch.setattr(sched, "usable_cores", lambda: 2)
    assert sched.check_scheduler("local:2") == "2 local worker processes"
    with pytest.raises(RimclError, match=r"local:3 asks for 3 worker .* 2 core\(s\): use local:2"):
        sched.check_scheduler("local:3")


@pytest.mark.parametrize("mode", ["ptv", "piv", "both"])
@pytest.mark.parametrize("spec", ["local:0", "local:100000", "silent"])
def test_every_mode_refuses_a_bad_scheduler_before_writing(
    tmp_path, monkeypatch, silent_listener, hang_guard, mode, spec
):
    monkeypatch.setattr(sched, "PROBE_SECONDS", 1.0)
    spec = silent_listener if spec == "silent" else spec
    out = tmp_path / "study"
    args = ["study", "--out", str(out), "--mode", mode, "--scheduler", spec, "--no-progress"]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.output
    assert ("local:N with N >= 1" if spec == "local:0" else spec.split(":")[0]) in lines[0]
    assert not out.exists()  # no scene.toml to refuse the corrected rerun


def test_local_workers_ignore_ctrl_c(device):
    with dist.connect("local:1", device_spec=device.name) as (client, _):
        handlers = client.run(signal.getsignal, signal.SIGINT)
    assert list(handlers.values()) == [signal.SIG_IGN]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
