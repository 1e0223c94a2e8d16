"""Every OpenCL kernel under Oclgrind (an OpenCL device simulator that checks each memory access):
out-of-bounds reads and writes and data races fail the build.

Oclgrind is seen by pyopencl as one more platform: an ICD file naming ``liboclgrind-rt-icd.so``
in a temporary vendors directory (``OCL_ICD_VENDORS``), and clpost picks it by name
(``device="oclgrind"``). ``tools/oclgrind_sweep.py`` runs every stage at every quality on tiny and
odd sizes in a subprocess (Oclgrind interprets each work-item: about 50 s of CPU); every Oclgrind report
on its stderr fails this test with the case that caused it.

Checks: ``OCLGRIND_DATA_RACES`` (races between work-items) and the always-on bounds checks of
global, local, private and constant memory. Not ``OCLGRIND_UNINITIALIZED``: with it Oclgrind
21.10 crashes (SIGSEGV inside the simulator) on most programs (dof, astigmatism, coma,
lateral_color, motion_blur, distortion, grain's Boolean model, lens_trace, the fused pointwise
kernels) and flags ibl_warp's accumulator, which ``enqueue_fill_buffer`` zeroes, as uninitialised.
``tools/oclgrind_compat.h`` works around Oclgrind 21.10's wrong integer min/max/clamp with scalar
bounds (tested below).

Also here, not needing Oclgrind: the host-side invariant behind the segfault of
``clpost bench`` at 3840×2160 (``distortion_bspline_tiles`` loading windows outside the
coefficient planes) and the bench keeping its measured rows when a later case fails.
"""
from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SWEEP = ROOT / "tools" / "oclgrind_sweep.py"
COMPAT = ROOT / "tools" / "oclgrind_compat.h"
ICD_LIBS = ("/usr/lib/oclgrind/liboclgrind-rt-icd.so", "/usr/lib/x86_64-linux-gnu/oclgrind/liboclgrind-rt-icd.so",
            "/usr/local/lib/liboclgrind-rt-icd.so")
# Oclgrind's report headers (src/core/Context.cpp, src/plugins/*): each report is a line like
# "Invalid read of size 4 at global memory address 0x…" followed by "\tKernel: <name>".
REPORT = re.compile(r"^(Invalid (read|write)|.*data race|Uninitialized|Work-group divergence|"
                    r"Oclgrind - OpenCL runtime error|.*out-of-bounds|Unaligned|Invalid)", re.I)

needs_oclgrind = pytest.mark.skipif(
    not any(os.path.exists(p) for p in ICD_LIBS),
    reason="Oclgrind is not installed (Debian/Ubuntu: apt-get install oclgrind; see README's test command)")


def _icd_lib() -> str:
    return next(p for p in ICD_LIBS if os.path.exists(p))


def _env(tmp_path: Path) -> dict:
    vendors = tmp_path / "icd"
    vendors.mkdir(exist_ok=True)
    (vendors / "oclgrind.icd").write_text(_icd_lib() + "\n")
    env = dict(os.environ)
    env.update(
        OCL_ICD_VENDORS=str(vendors), OPENCL_VENDOR_PATH=str(vendors),
        CLPOST_DEVICE="oclgrind",
        OCLGRIND_DATA_RACES="1",
        OCLGRIND_BUILD_OPTIONS=f"-include {COMPAT}",
        PYOPENCL_NO_CACHE="1",  # a cached binary would skip OCLGRIND_BUILD_OPTIONS
        PYTHONPATH=os.pathsep.join([str(ROOT)] + [p for p in [os.environ.get("PYTHONPATH")] if p]),
    )
    env.pop("CLPOST_EXPECT_INSTALLED", None)
    return env


def _reports(stderr: str) -> list[str]:
    """Each Oclgrind report with the sweep case it happened in (``=== <case>`` lines)."""
    out, case = [], "(before the first case)"
    lines = stderr.splitlines()
    for i, line in enumerate(lines):
        if line.startswith("=== "):
            case = line[4:]
        elif REPORT.match(line.strip()):
            kernel = next((ln.strip() for ln in lines[i + 1:i + 3] if ln.strip().startswith("Kernel:")), "")
            out.append(f"{case}: {line.strip()} {kernel}")
    return out


def _run(args, tmp_path, timeout=900):
    return subprocess.run([sys.executable, *args], env=_env(tmp_path), cwd=tmp_path, capture_output=True,
                          text=True, timeout=timeout)


_CANARY = r"""
import sys
import numpy as np, pyopencl as cl
from clpost.runtime import get_runtime
rt = get_runtime("oclgrind")
src = '''__kernel void oob(__global const float *a, __global float *b, const int n) {
    const int i = get_global_id(0);
    b[i] = a[i + n];                       /* reads one past the end for the last item */
}
__kernel void race(__global int *c) { c[0] = (int)get_global_id(0); }
__kernel void mm(__global int *o) {
    const int16 lane = (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    vstore16(clamp(lane - 3, 0, 9), 0, o);
    vstore16(min(lane, 5), 1, o);
    vstore16(max(lane, 5), 2, o);
}'''
p = cl.Program(rt.context, src).build()
mf = cl.mem_flags
a = cl.Buffer(rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.zeros(8, np.float32))
b = cl.Buffer(rt.context, mf.READ_WRITE, 32)
print("=== oob", file=sys.stderr, flush=True)
p.oob(rt.queue, (8,), None, a, b, np.int32(1)); rt.queue.finish()
print("=== race", file=sys.stderr, flush=True)
c = cl.Buffer(rt.context, mf.READ_WRITE, 4)
p.race(rt.queue, (16,), (16,), c); rt.queue.finish()
o = np.zeros(48, np.int32)
ob = cl.Buffer(rt.context, mf.READ_WRITE, o.nbytes)
p.mm(rt.queue, (1,), None, ob); cl.enqueue_copy(rt.queue, o, ob)
print("MINMAX", " ".join(map(str, o)))
"""


@needs_oclgrind
def test_the_harness_catches_an_out_of_bounds_read_and_a_race_and_fixes_scalar_minmax(tmp_path):
    """The detector itself: a kernel reading one float past its buffer and a kernel whose
    work-items all write one word must be reported (else the sweep's silence means nothing),
    and the integer min/max/clamp with scalar bounds give the OpenCL C results."""
    r = _run(["-c", _CANARY], tmp_path, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    reps = _reports(r.stderr)
    assert any("Invalid read" in x and "oob" in x for x in reps), r.stderr[-3000:]
    assert any("race" in x.lower() for x in reps), r.stderr[-3000:]
    got = np.array([int(v) for v in r.stdout.split("MINMAX", 1)[1].split()]).reshape(3, 16)
    lane = np.arange(16)
    np.testing.assert_array_equal(got, [np.clip(lane - 3, 0, 9), np.minimum(lane, 5), np.maximum(lane, 5)])


# Kernels the sweep does not reach: the other instantiations of the coma stencil and astigmatism
# gather macros (one kernel per tap count; the sweep runs the macro bodies through coma and
# astigmatism_t4 / astigmatism_exact) and the per-pixel bilinear `distortion`, which the stage
# does not enqueue (distortion_tiles + distortion_rest do its work); glare_multiply, which only the
# optional pyvkfft path enqueues (the spectra's product on the device; without pyvkfft the host FFT
# multiplies), when pyvkfft is not installed.
_VKFFT = importlib.util.find_spec("pyvkfft") is not None
NOT_SWEPT = {"astigmatism", "astigmatism_t8", "astigmatism_t16", "astigmatism_t32", "distortion"} | (
    set() if _VKFFT else {"glare_multiply"}) | {
    f"coma_{k}{s}" for k in "sc" for s in (4, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256)
} - {"coma_c4", "coma_c8"}


@needs_oclgrind
def test_every_kernel_is_clean_under_oclgrind(tmp_path):
    r = _run([str(SWEEP)], tmp_path)
    reps = _reports(r.stderr)
    assert not reps, (f"{len(reps)} Oclgrind report(s); first ones:\n" + "\n".join(reps[:20])
                      + "\n--- stderr tail ---\n" + r.stderr[-2000:])
    assert r.returncode == 0, r.stderr[-4000:]
    assert re.search(r"oclgrind_sweep: \d+ case\(s\) done", r.stderr), r.stderr[-2000:]
    ran = set(re.search(r"kernels run: (.*)", r.stderr).group(1).split())
    declared = set()
    for f in (ROOT / "kernels").glob("*.cl"):
        declared |= set(re.findall(r"__kernel\s+void\s+(\w+)", f.read_text()))
    missing = declared - ran - NOT_SWEPT
    assert not missing, f"kernels never run by tools/oclgrind_sweep.py: {sorted(missing)} (add a case)"


# -- item 12 without Oclgrind ---------------------------------------------------------------

def _window_bounds(model, src_size, src_k):
    """The smallest and largest offset into one coefficient plane that distortion_bspline_tiles
    loads for the listed tiles, every lane and every row inside the image, and the plane size."""
    from clpost.stages import distortion as D

    tiles, _ = D.bspline_tiles(model, src_size, src_k)
    sw, sh = src_size
    pw, ph = D.coef_pitch(sw), -(-(sh + 2 * D.PAD) // D.FIR_ROWS) * D.FIR_ROWS
    x0, y0, ox, oy = (a.astype(np.int64) for a in tiles.T)
    last = np.minimum(y0 + D.TILE, model.height) - 1
    cols = (x0 + ox - 1 + D.PAD, x0 + D.TILE - 1 + ox + 3 + D.PAD)
    rows = (y0 + oy - 1 + D.PAD, last + oy + 3 + D.PAD)
    return len(tiles), (cols[0].min(), cols[1].max()), (rows[0].min(), rows[1].max()), (pw, ph)


@pytest.mark.parametrize("size", [(1920, 1080), (48, 48)])
def test_bspline_tiles_windows_stay_inside_the_coefficient_planes(size):
    """The cause of the 4K bench segfault: a tile's lanes without a preimage loaded 5×5 windows
    up to 17 px beyond the render (19215 floats before the buffer at 3840×2160; at 1920×1080 5
    columns before a plane's rows, which is cheaper to check here). 1080p: the bench scenes'
    barrel model; 48×48: the render shifted 12.6 px against the calibration (the
    Oclgrind sweep's distortion-shift cases, which reported the reads before the fix)."""
    from clpost.bench import SCENES
    from clpost.calibration import OpenCVModel, render_intrinsics
    from clpost.camera import Camera

    w, h = size
    if size == (1920, 1080):
        model = SCENES["worst"].camera(w, h)[0].distortion
        ks = [render_intrinsics(model, size)]
    else:
        model = OpenCVModel.from_camera(Camera(), size)
        ks = [(model.fx, model.fy, model.cx - s * 12.6, model.cy - s * 12.6) for s in (1, -1)]
    for k in ks:
        n, cols, rows, (pw, ph) = _window_bounds(model, size, k)
        assert n > 0
        assert cols[0] >= 0 and cols[1] <= pw - 1, f"columns {cols} outside [0, {pw - 1}] for {k}"
        assert rows[0] >= 0 and rows[1] <= ph - 1, f"rows {rows} outside [0, {ph - 1}] for {k}"


def test_bench_logs_each_row_when_measured_and_keeps_them_when_a_later_case_fails(monkeypatch):
    from clpost import bench

    real = bench.bench_case
    calls = []

    def case(scene, w, h, **kw):
        calls.append(scene.name)
        if len(calls) == 2:
            raise RuntimeError("simulated failure of the second case")
        return real(scene, w, h, **kw)

    monkeypatch.setattr(bench, "bench_case", case)
    log = []
    with pytest.raises(RuntimeError, match="simulated"):
        bench.run(["worst", "full"], [(32, 16)], ["draft"], repeats=1, warmup=0, log=log.append)
    text = "\n".join(log)
    assert "bench: worst 32x16 draft: device" in text  # the row, as soon as it was measured
    assert "full 32x16 draft failed; the 1 row(s) measured before it" in text
    assert "worst 32x16 draft: plan" in text  # the measured row's table
