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
# Measured on the H200 on 2026-11-26 (docs/benchmarks.md, "Frames in flight (`Plan.submit`) on the
# H200"): the worst case end to end, bench on the GPU and on 16 PoCL cores, device_vs_device. Open:
# what bounds the full camera pipelined (--timeline), and why the 16-core PoCL gathers scaled so
# little against the 2-core box (dof 31.5 ms there vs 54 here at worst final): huge-page buffers
# on and off on the machine's own PoCL, per kernel (tools/ab_kernel.py --pages).
# dof's gather in its one-pixel form (CLPOST_DOF_VEC=1, bit-identical on PoCL) against the 8-wide
# form a GPU gets by default: if clearly faster, make it the GPU's default (gather_vector_width)
CB="bench --sizes 1920x1080 --scenes worst --qualities draft,final --device nvidia --repeats 7"
CLPOST_DOF_VEC=8 step 60 dof_vec8 python3 -W ignore -c "$C" $CB
CLPOST_DOF_VEC=1 step 60 dof_vec1 python3 -W ignore -c "$C" $CB
CLPOST_DOF_VEC=1 step 90 dof_vec1_vs_pocl python3 -W ignore tools/device_vs_device.py
step 60 end_to_end_full python3 -W ignore tools/end_to_end.py --device nvidia --scenes full --timeline --repeats 3
step 60 end_to_end_full_aux python3 -W ignore tools/end_to_end.py --device nvidia --scenes full --timeline --repeats 3 --aux-out
step 60 end_to_end_pull python3 -W ignore tools/end_to_end.py --device nvidia --focus-pull --scenes worst,full --qualities draft --in-flight 2
python3 -c "import pyopencl as cl; print([d.version + ' ' + d.driver_version for p in cl.get_platforms() for d in p.get_devices()])" 2>&1 | tail -1
# per kernel, 4 KiB pages (old) against huge pages (new), worst final and draft on the 16 PoCL cores
CLPOST_DEVICE=pocl step 100 pocl_pages_final python3 -W ignore tools/ab_kernel.py --scene worst --quality final --size 1920x1080 --repeats 5 --pages
CLPOST_DEVICE=pocl step 60 pocl_pages_draft python3 -W ignore tools/ab_kernel.py --scene worst --quality draft --size 1920x1080 --repeats 5 --pages
step 100 device_vs_device python3 -W ignore tools/device_vs_device.py
uptime
