"""OpenCL runtime: device choice by name, build errors, kernel sources found when installed."""
import os
import sysconfig
from pathlib import Path

import pytest

from clpost import KernelBuildError, OpenCLUnavailableError
from clpost.runtime import BUILD_OPTIONS, choose_device, get_runtime, kernels_dir


def test_default_device_builds_kernels():
    rt = get_runtime()
    prog = rt.program("__kernel void k(__global float *a) { a[0] = 1.0f; }", "k")
    assert prog is rt.program("__kernel void k(__global float *a) { a[0] = 1.0f; }", "k")  # cached


def test_device_by_name_substring_and_env(monkeypatch):
    dev = choose_device()
    sub = dev.name.strip()[:6]
    assert choose_device(sub.upper()).name == dev.name or sub.upper() in choose_device(sub.upper()).name.upper()
    monkeypatch.setenv("CLPOST_DEVICE", "no-such-device-xyz")
    with pytest.raises(OpenCLUnavailableError, match="no-such-device-xyz.*matches no OpenCL device.*have:"):
        choose_device()


def test_build_failure_names_kernel_options_and_log():
    rt = get_runtime()
    with pytest.raises(KernelBuildError) as exc:
        rt.program("__kernel void broken(__global float *a) { a[0] = undefined_name; }", "broken")
    msg = str(exc.value)
    assert "'broken' failed to build" in msg and "-cl-std=CL1.2" in msg and "undefined_name" in msg


def test_no_ieee_breaking_build_options():
    for bad in ("fast-relaxed-math", "finite-math-only", "denorms-are-zero", "unsafe-math"):
        assert not any(bad in o for o in BUILD_OPTIONS)


def test_pocl_cache_dir_is_set():
    assert os.environ.get("POCL_CACHE_DIR")


def test_kernels_come_from_the_installed_package_in_ci():
    d = kernels_dir()
    assert (d / "exposure.cl").is_file()
    if os.environ.get("CLPOST_EXPECT_INSTALLED"):
        site = Path(sysconfig.get_paths()["purelib"]).resolve()
        assert site in d.resolve().parents, f"kernels found at {d}, not in the installed wheel"


def test_pocl_matches_by_implementation_name():
    dev = choose_device("pocl")
    assert "pocl" in dev.platform.version.lower()


def test_the_newest_pocl_is_chosen_whatever_the_platform_order(monkeypatch):
    """pip's PoCL 3.0 beside a distribution's newer PoCL: the newer one, listed first or last (the
    ICD loader's order is not ours), for the default choice and for a name both match."""
    from types import SimpleNamespace

    import pyopencl as cl

    import clpost.runtime as R

    def dev(version, kind=cl.device_type.CPU, name="pthread-cpu"):
        plat = SimpleNamespace(name="Portable Computing Language", version=f"OpenCL 3.0 {version} Linux")
        return SimpleNamespace(platform=plat, name=name, type=kind)

    old, new, other = dev("PoCL 3.0-rc2"), dev("PoCL 5.0+debian"), dev("Intel(R) OpenCL 2024", name="Xeon")
    other.platform.name = "Intel(R) OpenCL"
    monkeypatch.setattr(R, "_compiler_problem", lambda d: None)
    for order in ([old, new, other], [other, new, old], [new, other, old]):
        monkeypatch.setattr(R, "list_devices", lambda order=order: list(order))
        assert R.choose_device() is new
        assert R.choose_device("pocl") is new
    gpu = dev("CUDA 13.0", kind=cl.device_type.GPU, name="H200")
    monkeypatch.setattr(R, "list_devices", lambda: [old, new, gpu])
    assert R.choose_device() is gpu


def test_device_option_after_the_subcommand(capsys):
    from clpost.cli import main

    assert main(["bench", "--device", "no-such-device-xyz", "--sizes", "8x8"]) == 2
    assert "no-such-device-xyz" in capsys.readouterr().err


_SRC = "__kernel void fill(__global float *a, const int n, const float v) { int i = get_global_id(0); if (i < n) a[i] = v + i; }"


def test_kernels_cached_per_program_and_name_and_defines():
    rt = get_runtime()
    k = rt.kernel(_SRC, "fill")
    assert rt.kernel(_SRC, "fill") is k
    assert rt.kernel(_SRC, "fill", {"X": 1}) is not k  # other defines: another program
    assert set(rt.kernels(_SRC, "fill")) == {"fill"} and rt.kernels(_SRC, "fill")["fill"] is k


def test_constant_uploaded_once_per_content_key():
    import pyopencl as cl
    import numpy as np

    rt = get_runtime()
    a = np.arange(7, dtype=np.float32) * 0.37
    buf = rt.constant(a)
    assert rt.constant(a.copy()) is buf  # same content, same buffer
    assert rt.constant(a + 1) is not buf
    out = np.empty_like(a)
    cl.enqueue_copy(rt.queue, out, buf, is_blocking=True)
    np.testing.assert_array_equal(out, a)
    calls = []
    make = lambda: calls.append(1) or a  # noqa: E731
    b1, b2 = rt.constant(make, key=("test", 1)), rt.constant(make, key=("test", 1))
    assert b1 is b2 and calls == [1]


def test_scratch_reused_per_owner_name_and_shape():
    import numpy as np

    class Owner:
        pass

    rt, o1, o2 = get_runtime(), Owner(), Owner()
    b = rt.scratch(o1, "x", (4, 5))
    assert rt.scratch(o1, "x", (4, 5)) is b
    assert rt.scratch(o2, "x", (4, 5)) is not b
    assert rt.scratch(o1, "y", (4, 5)) is not b
    b2 = rt.scratch(o1, "x", (4, 6))
    assert b2 is not b and b2.size == 4 * 6 * 4
    assert rt.scratch(o1, "x", (4, 6), np.int32) is not b2
    made = []
    assert rt.cached(o1, "plan", 1, lambda: made.append(1) or "a") == "a"
    assert rt.cached(o1, "plan", 1, lambda: made.append(1) or "b") == "a" and made == [1]
    assert rt.cached(o1, "plan", 2, lambda: "c") == "c"


def test_launch_rounds_global_size_to_whole_work_groups():
    import numpy as np
    import pyopencl as cl

    rt = get_runtime()
    n = 37  # not a multiple of the work-group: the kernel guards its bound
    buf = rt.empty((n,))
    ev = rt.launch(rt.kernel(_SRC, "fill"), (n,), (8,), buf, np.int32(n), np.float32(2.0))
    out = np.empty(n, np.float32)
    cl.enqueue_copy(rt.queue, out, buf, wait_for=[ev], is_blocking=True)
    np.testing.assert_array_equal(out, 2.0 + np.arange(n))
    from clpost.runtime import round_up
    assert round_up(37, 8) == 40 and round_up(40, 8) == 40


def test_large_buffers_on_pocl_live_in_huge_page_aligned_host_memory(monkeypatch):
    """Runtime.empty on PoCL's CPU device: buffers of at least a huge page are USE_HOST_PTR
    buffers on 2 MiB-aligned, MADV_HUGEPAGE memory of exactly the asked size, and a kernel and a
    round trip see the same data as in a plain buffer; CLPOST_HUGE_PAGES=0 (read by each new
    runtime) and small buffers keep plain ones."""
    import numpy as np
    import pyopencl as cl

    from clpost.runtime import HUGE_PAGE, Runtime

    rt = get_runtime()
    if not rt.huge_pages:
        pytest.skip(f"not PoCL's CPU device: {rt.name}")
    n = HUGE_PAGE // 4 + 37  # not a whole number of huge pages
    buf = rt.empty((n,))
    assert buf.flags & cl.mem_flags.USE_HOST_PTR and buf.size == 4 * n
    assert buf.hostbuf.ctypes.data % HUGE_PAGE == 0
    assert not rt.empty((1000,)).flags & cl.mem_flags.USE_HOST_PTR
    ev = rt.launch(rt.kernel(_SRC, "fill"), (n,), (64,), buf, np.int32(n), np.float32(2.0))
    out = np.empty(n, np.float32)
    cl.enqueue_copy(rt.queue, out, buf, wait_for=[ev], is_blocking=True)
    np.testing.assert_array_equal(out, 2.0 + np.arange(n, dtype=np.float32))
    host = np.random.default_rng(0).random(n, dtype=np.float32)
    cl.enqueue_copy(rt.queue, buf, host, is_blocking=True)
    cl.enqueue_copy(rt.queue, out, buf, is_blocking=True)
    np.testing.assert_array_equal(out, host)
    # the memory outlives the buffer object until the queue has run what was queued on it
    import gc
    import weakref
    host_ref = weakref.ref(buf.hostbuf.base)
    rt.launch(rt.kernel(_SRC, "fill"), (n,), (64,), buf, np.int32(n), np.float32(3.0))
    del buf
    gc.collect()
    rt.queue.finish()
    gc.collect()
    assert host_ref() is None
    monkeypatch.setenv("CLPOST_HUGE_PAGES", "0")
    plain = Runtime(rt.device)
    assert not plain.huge_pages and not plain.empty((n,)).flags & cl.mem_flags.USE_HOST_PTR
