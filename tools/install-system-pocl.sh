#!/usr/bin/env bash
# Installs the distribution's PoCL (CPU OpenCL) where the pip one cannot compile.
#
# The PoCL inside the pyopencl wheel is built on LLVM 14, which does not know CPUs newer
# than it (AMD Zen 5 among them) and then fails every build with "unknown target CPU
# 'generic'". Debian's pocl-opencl-icd (PoCL 3.1, LLVM 15) works there. rimcl skips
# devices that cannot compile, so having both installed is harmless.
set -euo pipefail
if grep -qs libpocl /etc/OpenCL/vendors/*.icd; then
    exit 0
fi
if ! command -v apt-get >/dev/null; then
    echo "install-system-pocl: no apt-get here; install your distribution's PoCL if 'rimcl devices' finds no usable device" >&2
    exit 0
fi
SUDO=""
if [ "$(id -u)" != 0 ]; then
    if command -v sudo >/dev/null; then SUDO="sudo"; else
        echo "install-system-pocl: not root; run: apt-get install pocl-opencl-icd" >&2
        exit 0
    fi
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq pocl-opencl-icd >/dev/null
