#!/usr/bin/env bash
# The measurements issue 20 still wants from a lent GPU machine, in one call (≈ 5 min; every step has
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
# Measured on H200s on 2026-11-26/27 (docs/benchmarks.md, "Frames in flight (`Plan.submit`) on
# the H200" and "The H200 again"): end to end (worst final 330-359 fps, the full camera 542-648 fps
# with out=), dof's one-pixel gather (now a GPU's default), two PoCLs, huge pages (not it). Open:
# the one-pixel forms' kernel times against the 16-lane forms on the GPU (gpu_forms; its 16-lane
# forms are slow there, hence 3 repeats), where worst final's 2.6 ms go per kernel (dof_levels and
# the B-spline gather were the largest), and the full camera without out= (host copy rates).
# Only 8 files come back from a lent machine: one file per step, 8 steps at most (8 now).
step 120 forms_worst_final python3 -W ignore tools/gpu_forms.py --device nvidia --scene worst --qualities final --repeats 3
CLPOST_DEVICE=nvidia step 60 kernels_worst_final python3 -W ignore tools/ab_kernel.py --scene worst --quality final --size 1920x1080 --repeats 5
step 60 end_to_end python3 -W ignore tools/end_to_end.py --device nvidia --scenes worst,full --qualities draft,final --in-flight 2 --repeats 3
step 60 end_to_end_full_aux python3 -W ignore tools/end_to_end.py --device nvidia --scenes full --timeline --repeats 3 --aux-out
step 30 host_copy python3 -W ignore tools/transfer_bench.py --device nvidia --repeats 7
step 80 bench_pocl python3 -W ignore -c "$C" $B --device pocl --repeats 3
step 110 device_vs_device python3 -W ignore tools/device_vs_device.py
# the front layer (session 12, never on a GPU yet): its one-pixel kernels' cost against dof's
step 40 bench_layers python3 -W ignore -c "$C" bench --sizes 1920x1080 --scenes layers --qualities draft,final --device nvidia --repeats 7
uptime
