#!/usr/bin/env bash
# GPU checks on a lent NVIDIA machine (no network there): run from the repository root with
# the Python wheels rimcl needs beyond that machine's image in .whl/ (pyopencl, pytools,
# platformdirs, siphash24, tomli_w, miepython, cf-units, cftime). Results go to $OUT
# (default ./gpu-out): log.txt (every step's output, in order) and results.tar.gz (the
# kernel-shape cache, the traced ray set for device_agreement.py compare, JSON results and
# the bench folder); the device tool brings back at most 8 files, hence two.
#
# 0. the OpenCL platforms the machine offers (the script stops here without an NVIDIA one);
# 1. the GPU's kernel shapes measured (rimcl bench --tune; every later step uses the cache);
# 2. kernels build and `rimcl verify` passes on the GPU;
# 3. the device tests run with the GPU as the test device;
# 4. a fixed ray set is traced for comparison with PoCL (device_agreement.py compare);
# 5. ray-steps/s per interpolation and precision (speed.py), and `rimcl bench --quick`;
# 6. both engines end to end (pipeline.py, cases C1 and C3) and one case of 2e4 tracers x
#    1e4 rays (SCALE_TRACERS). STEPS names the steps to run (default: all).
# Each step has its own time limit (seconds, below), so one slow step cannot cost the rest;
# in all they stay under 11 minutes.
set -uo pipefail
OUT=${OUT:-gpu-out}
mkdir -p "$OUT/results"
OUT=$(cd "$OUT" && pwd)  # absolute: the steps below run from /tmp
RES="$OUT/results"
LOG="$OUT/log.txt"
export PYTHONUNBUFFERED=1
export RIMCL_SHAPE_CACHE="$RES/kernel_shapes.json"
STEPS=${STEPS:-devices tune verify tests agreement speed bench pipeline scale}
step() {  # step NAME SECONDS COMMAND...: run with a limit, output to the log
    local name=$1 limit=$2; shift 2
    case " $STEPS " in *" $name "*) ;; *) return ;; esac
    local start=$SECONDS
    echo "=== $name (limit ${limit} s)" | tee -a "$LOG"
    timeout "$limit" "$@" 2>&1 | tee -a "$LOG"
    echo "=== $name: rc ${PIPESTATUS[0]}, $((SECONDS - start)) s" | tee -a "$LOG"
}
pack() { tar -czf "$OUT/results.tar.gz" -C "$RES" . ; }
trap pack EXIT
# the image ships NVIDIA's OpenCL library but registers only PoCL with the ICD loader
mkdir -p /etc/OpenCL/vendors
if [ ! -e /etc/OpenCL/vendors/nvidia.icd ]; then
    lib=$(ldconfig -p 2>/dev/null | awk '/libnvidia-opencl.so.1/ {print $NF; exit}')
    [ -n "$lib" ] || lib=$(find /usr/local/nvidia /usr/lib* -name 'libnvidia-opencl.so.1' 2>/dev/null | head -1)
    echo "${lib:-libnvidia-opencl.so.1}" > /etc/OpenCL/vendors/nvidia.icd
fi
{ nvidia-smi -L; cat /etc/OpenCL/vendors/*.icd; python3 --version; } 2>&1 | tee -a "$LOG"
python3 -m pip install -q --no-index --no-deps --no-compile --upgrade --target /tmp/site .whl/*.whl 2>&1 | tee -a "$LOG"
python3 -m pip install -q --no-deps --no-build-isolation --no-compile --upgrade --target /tmp/site . 2>&1 | grep -v WARNING | tee -a "$LOG"
export PYTHONPATH=/tmp/site
repo=$(pwd)
cd /tmp  # import the installed package, not the source tree
step devices 60 python3 -m rimcl devices
if ! python3 -c "import pyopencl as cl, sys; sys.exit(not any('NVIDIA' in p.name for p in cl.get_platforms()))"; then
    echo "no NVIDIA OpenCL platform: stopping" | tee -a "$LOG"; exit 3
fi
step tune 60 python3 -m rimcl bench --tune --device nvidia
step verify 60 python3 -m rimcl verify --device nvidia
device_tests=$(cd "$repo" && ls tests/test_{trace,kernels_build,device,camera,measure,cli_core,shapes}.py \
    tests/test_{interp,step,auto,method,speed,engine}*.py 2>/dev/null | sed "s|^|$repo/|")
step tests 140 env RIMCL_TEST_DEVICE=nvidia python3 -m pytest -q -n 8 -p no:cacheprovider -p no:benchmark \
    --rootdir "$repo" $device_tests
step agreement 40 python3 "$repo/benchmarks/device_agreement.py" trace --device nvidia \
    --interp trilinear texture bspline3 -o "$RES/agreement_gpu.npz"
step speed 60 python3 "$repo/benchmarks/speed.py" --device nvidia --repeats 3 --json "$RES/speed.json"
step bench 40 python3 -m rimcl bench --quick --device nvidia --out "$RES/bench"
step pipeline 100 python3 "$repo/benchmarks/pipeline.py" --device nvidia --cases C1,C3 \
    --tracers 100 --paper-tracers 40 --json "$RES/pipeline.json"
step scale 80 python3 "$repo/benchmarks/pipeline.py" --device nvidia --cases "" \
    --scale-run "${SCALE_TRACERS:-20000}" --json "$RES/scale.json"
