#!/usr/bin/env bash
# GPU checks on a lent NVIDIA machine (no network there): run from the repository root with
# the Python wheels rimcl needs beyond that machine's image in .whl/ (pyopencl, pytools,
# platformdirs, siphash24, tomli_w). Results go to $OUT (default ./gpu-out).
#
# 0. the GPU's kernel shapes measured (rimcl bench --tune; the cache lands in $OUT);
# 1. kernels build and `rimcl verify` passes on the GPU;
# 2. the device tests run with the GPU as the test device;
# 3. a fixed ray set is traced for comparison with PoCL (device_agreement.py compare);
# 4. ray-steps/s per interpolation and precision (speed.py), and `rimcl bench --quick`;
# 5. both engines end to end (pipeline.py) and one case of 1e5 tracers x 1e4 rays.
set -uo pipefail
OUT=${OUT:-gpu-out}
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)  # absolute: the steps below run from /tmp
export PYTHONUNBUFFERED=1
# the measured kernel shapes come back with the results (and every later step uses them)
export RIMCL_SHAPE_CACHE="$OUT/kernel_shapes.json"
# the image ships NVIDIA's OpenCL library but registers only PoCL with the ICD loader
[ -e /etc/OpenCL/vendors/nvidia.icd ] || echo libnvidia-opencl.so.1 > /etc/OpenCL/vendors/nvidia.icd
python3 -m pip install -q --no-index --no-deps --no-compile --upgrade --target /tmp/site .whl/*.whl
python3 -m pip install -q --no-deps --no-build-isolation --no-compile --upgrade --target /tmp/site . 2>&1 | grep -v WARNING
export PYTHONPATH=/tmp/site
repo=$(pwd)
cd /tmp  # import the installed package, not the source tree
python3 -m rimcl bench --tune --device nvidia 2>&1 | tee "$OUT/tune.txt"
python3 -m rimcl devices 2>&1 | tee "$OUT/devices.txt"
python3 -m rimcl verify --device nvidia 2>&1 | tee "$OUT/verify.txt"
device_tests=$(cd "$repo" && ls tests/test_{trace,kernels_build,device,camera,measure,cli_core,shapes}.py \
    tests/test_{interp,step,auto,method,speed,engine}*.py 2>/dev/null | sed "s|^|$repo/|")
RIMCL_TEST_DEVICE=nvidia python3 -m pytest -q -p no:cacheprovider --rootdir "$repo" $device_tests \
    2>&1 | tail -25 | tee "$OUT/tests.txt"
python3 "$repo/benchmarks/device_agreement.py" trace --device nvidia \
    --interp trilinear texture bspline3 -o "$OUT/agreement_gpu.npz" | tee "$OUT/agreement.txt"
python3 "$repo/benchmarks/speed.py" --device nvidia --json "$OUT/speed.json" | tee "$OUT/speed.txt"
python3 -m rimcl bench --quick --device nvidia --out "$OUT/bench" 2>&1 | tail -30 | tee "$OUT/bench.txt"
python3 "$repo/benchmarks/pipeline.py" --device nvidia --paper-tracers 2000 --scale-run 100000 \
    --json "$OUT/pipeline.json" 2>&1 | tee "$OUT/pipeline.txt"
