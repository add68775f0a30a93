#!/bin/bash
# Run benchmarks/speed/bench_gpu.py on a GPU machine without a package index (the device tool of this workplace).
#
# ../shared/tools/gpu-wheels packs the pinned packages into .gpu/p1 .. .gpu/p3 (~37 MiB each: one call carries at
# most 64 MiB with the tree). A carried folder does not stay in the repository copy for the next call, so each of
# the first calls copies its part to /tmp, which stays while the machine is warm (30 s between calls):
#   run carry=[".gpu/p1"] command: cp .gpu/p1/chunk /tmp/c1
#   run carry=[".gpu/p2"] command: cp .gpu/p2/chunk /tmp/c2
#   run carry=[".gpu/p3"] command: bash benchmarks/speed/bench_gpu_device.sh 520     (timeout_s ~590)
# with array-api-compat's wheel (not in the machine's image) put in .gpu/p3 beforehand:
#   pip download --no-deps --only-binary=:all: -d .gpu/p3 array-api-compat==1.16.0
# Kernels compiled ahead (no GPU needed), packed into the last part (C flat and rough: ~2.5 MiB with xz):
#   python -m margin_rl.train kernels --env margin_rl/AnymalC-v1 --recipe robust --cache build/warp-kernels
#   python -m margin_rl.train kernels --env margin_rl/AnymalC-Rough-v1 --recipe rough --cache build/warp-kernels
#   tar cJf .gpu/p3/kernels.tar.xz -C build warp-kernels
# Arguments: the benchmark's time limit in seconds (default 520), then any further arguments of bench_gpu.py.
set -e
if [ -f .gpu/p3/kernels.tar.xz ]; then
  tar xJf .gpu/p3/kernels.tar.xz -C /tmp && export WARP_CACHE_PATH=/tmp/warp-kernels
fi
cat /tmp/c1 /tmp/c2 .gpu/p3/chunk | xz -d | tar xf - -C /tmp
export PYTHONPATH=/tmp/site GIT_PYTHON_REFRESH=quiet PYTHONUNBUFFERED=1
python3 -m pip install -q --no-index --no-deps --no-build-isolation --no-compile --target /tmp/site \
  .gpu/p3/array_api_compat-*.whl .
nvidia-smi > "$OUT/nvidia_smi.txt" 2>&1 || true
# From a copy of benchmarks/ outside the repository: bench_gpu.py puts its parent folder first on sys.path, and in
# the repository that would import the source folder margin_rl/ (without envs/ and train/) instead of the install.
rm -rf /tmp/bench && mkdir /tmp/bench && cp -r benchmarks /tmp/bench/
cd /tmp/bench
limit=${1:-520}
shift || true
set +e
timeout "$limit" python3 benchmarks/speed/bench_gpu.py --device cuda:0 --out "$OUT" "$@" 2>&1 | tee "$OUT/bench_gpu.log"
echo "bench_gpu.py exit status ${PIPESTATUS[0]}"
