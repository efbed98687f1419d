"""tools/install-system-pocl.sh waits for apt's lock instead of failing (issue 20, item 6)."""

import os
import shutil
import subprocess
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "tools" / "install-system-pocl.sh"


def _run(tmp_path, locked_calls, wait_s="30"):
    """The script with a fake apt-get that reports a held lock ``locked_calls`` times."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    log, count = tmp_path / "apt.log", tmp_path / "count"
    count.write_text("0")
    fake = bin_dir / "apt-get"
    fake.write_text(
        "#!/bin/bash\n"
        f'echo "$*" >> {log}\n'
        f"n=$(cat {count}); echo $((n + 1)) > {count}\n"
        f"if [ $n -lt {locked_calls} ]; then\n"
        '  echo "E: Could not get lock /var/lib/apt/lists/lock. It is held by process 42 (apt)"'
        " >&2\n  exit 100\nfi\n"
    )
    fake.chmod(0o755)
    env = {
        **os.environ,
        "PATH": f"{bin_dir}:{os.environ['PATH']}",
        "RIMCL_ICD_DIR": str(tmp_path / "vendors"),
        "RIMCL_APT_WAIT_S": wait_s,
        "RIMCL_APT_POLL_S": "0.05",
    }
    done = subprocess.run(
        ["bash", str(SCRIPT)], env=env, capture_output=True, text=True, timeout=60
    )
    return done, log.read_text().splitlines() if log.exists() else []


pytestmark = pytest.mark.skipif(
    shutil.which("bash") is None or os.geteuid() != 0, reason="needs bash, run as root"
)


def test_the_install_waits_for_apt_s_lock(tmp_path):
    done, calls = _run(tmp_path, locked_calls=3)
    assert done.returncode == 0, done.stderr
    assert done.stderr.count("holds apt's lock; waiting") == 1
    assert [call.split()[-1] for call in calls] == ["-qq"] * 4 + ["pocl-opencl-icd"]
    assert all("DPkg::Lock::Timeout=30" in call for call in calls)


def test_a_lock_held_too_long_or_another_failure_is_reported(tmp_path):
    done, _ = _run(tmp_path, locked_calls=10**6, wait_s="1")
    assert done.returncode != 0 and "Could not get lock" in done.stderr
