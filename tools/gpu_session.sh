#!/usr/bin/env bash
# The measurements issue 20 wants from a lent GPU machine, in one call (≈ 5 min; every step has
# its own time limit so one slow step cannot eat the others'). Run from the repository root with
# clpost and its dependencies importable (PYTHONPATH) and the NVIDIA OpenCL ICD registered; each
# step writes its output to $OUT (default ./gpu_out), the figures docs/benchmarks.md quotes.
#
#   OUT=/tmp/gpu bash tools/gpu_session.sh
#
# Order = priority: what no CPU can measure first (frames in flight and end to end on the GPU,
# GPU-vs-CPU agreement), then the quiet many-core CPU rows of the targets table.
set -u
OUT=${OUT:-gpu_out}; mkdir -p "$OUT"
C="import sys; from clpost.cli import main; sys.exit(main())"
B="bench --sizes 1920x1080 --scenes worst,no_defocus,full --qualities draft,final"
step() {  # step SECONDS NAME COMMAND...: run with a limit, keep its output, say how it ended
    local limit=$1 name=$2; shift 2
    timeout "$limit" "$@" > "$OUT/$name.txt" 2>&1; echo "$name rc $?"; tail -n 12 "$OUT/$name.txt"
}
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>/dev/null; nproc; git log --oneline -1 2>/dev/null
if python3 -c "import pytest" 2>/dev/null; then
    CLPOST_DEVICE=nvidia step 90 submit_tests python3 -m pytest -q -x -p no:cacheprovider tests/test_plan_submit.py
fi
step 150 end_to_end python3 -W ignore tools/end_to_end.py --device nvidia
step 90 end_to_end_pull python3 -W ignore tools/end_to_end.py --device nvidia --focus-pull --scenes worst,full --qualities draft
step 90 bench_gpu python3 -W ignore -c "$C" $B --device nvidia --repeats 7
step 100 device_vs_device python3 -W ignore tools/device_vs_device.py
step 120 bench_pocl python3 -W ignore -c "$C" $B --device pocl --repeats 5
step 120 process_pocl python3 -W ignore tools/process_throughput.py --size 1920x1080 --frames 8 --rounds 2 --device pocl
uptime
