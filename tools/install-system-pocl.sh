#!/usr/bin/env bash
# Installs the distribution's PoCL (CPU OpenCL) where the pip one cannot compile.
#
# The PoCL inside the pyopencl wheel is built on LLVM 14, which does not know CPUs newer
# than it (AMD Zen 5 among them) and then fails every build with "unknown target CPU
# 'generic'"; on a Zen 4 its build of rimcl's image kernel fails. Debian's pocl-opencl-icd
# (PoCL 3.1, LLVM 15) works there. rimcl probes every device, skips those that cannot build
# its kernels and prefers the newest PoCL, so having both installed is harmless.
#
# Another package manager (unattended-upgrades, a first-boot apt run) may hold apt's lock:
# the script then waits for it, up to RIMCL_APT_WAIT_S seconds (default 600), instead of
# failing. RIMCL_ICD_DIR (default /etc/OpenCL/vendors) is where registered drivers are.
set -euo pipefail
ICD_DIR="${RIMCL_ICD_DIR:-/etc/OpenCL/vendors}"
WAIT_S="${RIMCL_APT_WAIT_S:-600}"
POLL_S="${RIMCL_APT_POLL_S:-5}"
if grep -qs libpocl "$ICD_DIR"/*.icd; then
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

# apt-get with its arguments, run again while another process holds apt's or dpkg's lock
apt_waiting() {
    local started=$SECONDS told="" output
    while true; do
        if output=$($SUDO apt-get -o DPkg::Lock::Timeout="$WAIT_S" "$@" 2>&1); then
            return 0
        fi
        if ! grep -qiE "could not get lock|unable to lock|unable to acquire" <<<"$output" \
            || [ $((SECONDS - started)) -ge "$WAIT_S" ]; then
            echo "$output" >&2
            return 1
        fi
        if [ -z "$told" ]; then
            echo "install-system-pocl: another package manager holds apt's lock; waiting (up to $WAIT_S s)" >&2
            told=1
        fi
        sleep "$POLL_S"
    done
}
apt_waiting update -qq
apt_waiting install -y -qq pocl-opencl-icd >/dev/null
