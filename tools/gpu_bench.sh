#!/usr/bin/env bash
# oaraim bench on a GPU machine, as run through the `device` tool (docs/benchmarks.md):
# installs oaraim and the wheels that machine lacks (carried in .whl/) into /tmp/site, then
# runs the accelerator rows one part per process so that each finished part's JSON is kept
# even if a later part runs out of time. Usage: tools/gpu_bench.sh OUT_DIR [PARTS...]
# PARTS: mhss, world-map, fig4, latency (default: all four, in that order). That machine
# reaches no network: OARAIM_DATA names a folder with the data files the studies read
# (almanac/almmops.txt, almanac/alm_gal_ed259.txt, nav/brdc0010.22n).
set -u -o pipefail
out=${1:?usage: tools/gpu_bench.sh OUT_DIR [PARTS...]}
shift
parts=("$@")
[ ${#parts[@]} -eq 0 ] && parts=(mhss world-map fig4 latency)
mkdir -p "$out"
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl || exit 1
python3 -m pip install -q --no-index --no-deps --no-build-isolation --no-cache-dir \
    --target /tmp/site . || exit 1
export PYTHONPATH=/tmp/site PYTHONUNBUFFERED=1 PATH=/tmp/site/bin:$PATH
# the installed package, not the source folder oaraim/ of the checkout (the source tree maps
# geometry/, araim/, ... into oaraim only when installed)
[ -n "${OARAIM_DATA:-}" ] && export OARAIM_DATA=$(realpath "$OARAIM_DATA")
cd /tmp || exit 1
# several processes (the start-up probe, Dask workers) must share the card: no preallocation
export XLA_PYTHON_CLIENT_PREALLOCATE=false OARAIM_CACHE=/tmp/oaraim-cache
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
python3 -c "import jax; print('jax', jax.__version__, jax.devices())"
for p in "${parts[@]}"; do
    t0=$(date +%s)
    case $p in
        mhss) args=(--only mhss --mhss-batch 1048576) ;;
        world-map) args=(--only "" --world-map) ;;
        fig4) args=(--only "" --fig4) ;;
        *) args=(--only "$p") ;;
    esac
    python3 -m oaraim bench "${args[@]}" --json "$out/bench_gpu_$p.json" 2>&1 \
        | tee "$out/bench_gpu_$p.log"
    echo "part $p: rc ${PIPESTATUS[0]}, $(( $(date +%s) - t0 )) s"
done
