"""The installed wheel (not the checkout) carries the kernels and runs ``rimcl --help``."""

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(out), str(ROOT)],
        check=True,
    )
    (found,) = out.glob("rimcl-*.whl")
    return found


def test_wheel_contains_kernels_and_cli(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    kernels = {Path(name).name for name in names if name.startswith("rimcl/kernels/")}
    shipped = {p.name for p in (ROOT / "cl").iterdir() if p.suffix in (".cl", ".h")}
    assert shipped and shipped <= kernels
    assert "rimcl/cli/main.py" in names and "rimcl/optics/trace.py" in names
    assert any(name.startswith("rimcl-") and name.endswith("entry_points.txt") for name in names)


def test_installed_wheel_runs_outside_the_checkout(wheel, tmp_path):
    target = tmp_path / "site"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--no-deps",
            "-q",
            "--target",
            str(target),
            str(wheel),
        ],
        check=True,
    )
    code = (
        "import rimcl, rimcl.core.program, sys; from rimcl.cli.main import cli;"
        "print(rimcl.__file__); print(rimcl.core.program.kernel_dir());"
        "sys.argv = ['rimcl', '--help']; cli()"
    )
    env = {**os.environ, "PYTHONPATH": str(target)}
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    module_file, kernel_dir, *help_text = done.stdout.splitlines()
    assert module_file.startswith(str(target)) and kernel_dir.startswith(str(target))
    assert (Path(kernel_dir) / "trace.cl").is_file()
    assert any("Commands" in line for line in help_text)
