"""The branch-free elementary functions of kernels/fastmath.cl (clp_log2, clp_exp2, clp_exp2_bounded, clp_cos2pi,
clp_cossin2pi_half) against float64 numpy over the whole float32 range, including the IEEE special values."""
import numpy as np
import pytest

cl = pytest.importorskip("pyopencl")

from clpost.codegen import library  # noqa: E402
from clpost.runtime import get_runtime  # noqa: E402

_SRC = library() + """
__kernel void fm(__global const float *x, __global float *out, const int n) {
    const int i = get_global_id(0);
    if (i >= n) return;
    out[i] = clp_log2(x[i]);
    out[n + i] = clp_exp2(x[i]);
    out[2 * n + i] = clp_cos2pi(x[i]);
    out[3 * n + i] = clp_exp2_bounded(clamp(x[i], -126.0f, 126.0f));
    float s;
    out[4 * n + i] = clp_cossin2pi_half(clamp(x[i], -0.5f, 0.5f), &s);
    out[5 * n + i] = s;
}
"""


def _run(x):
    rt = get_runtime()
    x = np.ascontiguousarray(x, np.float32)
    prog = rt.program(_SRC, "fm")
    out = np.empty(6 * x.size, np.float32)
    xb = cl.Buffer(rt.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=x)
    ob = cl.Buffer(rt.context, cl.mem_flags.WRITE_ONLY, out.nbytes)
    cl.Kernel(prog, "fm")(rt.queue, (x.size,), None, xb, ob, np.int32(x.size))
    cl.enqueue_copy(rt.queue, out, ob)
    return out.reshape(6, -1)


def _ulp_err(got, want):
    want32 = want.astype(np.float32)
    return np.abs(got.astype(np.float64) - want) / np.spacing(np.abs(want32)).astype(np.float64)


def test_log2_whole_range():
    rng = np.random.default_rng(1)
    x = np.concatenate([
        np.exp2(rng.uniform(-126, 128, 200000)),                # every normal binade
        1.0 + rng.uniform(-1e-3, 1e-3, 20000),                  # near 1, where log2 ~ 0
        np.array([np.float32(1.17549435e-38), 1.0, 2.0, 0.5, np.sqrt(2.0), 3.4e38])])
    x = x.astype(np.float32)
    got = _run(x)[0].astype(np.float64)
    want = np.log2(x.astype(np.float64))
    err = np.abs(got - want)
    tol = np.maximum(2e-7, 2.0 * np.spacing(np.abs(want).astype(np.float32)))
    k = int(np.argmax(err / tol))
    assert np.all(err <= tol), f"worst at x={x[k]!r}: {got[k]!r} vs {want[k]!r}"


def test_exp2_whole_range():
    rng = np.random.default_rng(2)
    x = np.concatenate([rng.uniform(-126, 127.9, 200000), rng.uniform(-149, -126, 2000),
                        np.arange(-126, 128, dtype=np.float64)]).astype(np.float32)
    got = _run(x)[1]
    want = np.exp2(x.astype(np.float64))
    normal = want >= 1.17549435e-38
    err = _ulp_err(got[normal], want[normal])
    k = int(np.argmax(err))
    assert err.max() <= 2.0, f"worst at x={x[normal][k]!r}: {err[k]:.2f} ulp"
    # subnormal results: within one subnormal step (1.4e-45) of float64 rounded
    assert np.all(np.abs(got[~normal] - want[~normal]) <= 2 * 1.4013e-45)


def test_exp2_special_values():
    x = np.array([0.0, -0.0, np.inf, -np.inf, 128.0, 200.0, -200.0, -150.0], np.float32)
    ex = _run(x)[1]
    assert ex[0] == 1.0 and ex[1] == 1.0
    assert ex[2] == np.inf and ex[4] == np.inf and ex[5] == np.inf
    assert ex[3] == 0.0 and ex[6] == 0.0 and ex[7] == 0.0


def test_cos2pi():
    rng = np.random.default_rng(3)
    u = np.concatenate([rng.uniform(0, 1, 200000), rng.uniform(-50, 50, 20000),
                        np.array([0, 0.25, 0.5, 0.75, 1.0])]).astype(np.float32)
    got = _run(u)[2].astype(np.float64)
    want = np.cos(2 * np.pi * u.astype(np.float64))
    err = np.abs(got - want)
    k = int(np.argmax(err))
    assert err.max() < 2.5e-7, f"worst at u={u[k]!r}: {got[k]!r} vs {want[k]!r}"


def test_cossin2pi_half_on_its_domain():
    # |v| <= 1/2: Box-Muller's u2 - 1/2 (kernels/random.cl), every 24-bit uniform's value included
    rng = np.random.default_rng(4)
    v = np.concatenate([(np.arange(0, 1 << 24, 7) + 0.5) / 2.0 ** 24 - 0.5, rng.uniform(-0.5, 0.5, 100000),
                        [-0.5, -0.25, 0.0, 0.25, 0.5, -1e-30, 1e-30]]).astype(np.float32)
    out = _run(v)
    for got, want in ((out[4], np.cos(2 * np.pi * v.astype(np.float64))),
                      (out[5], np.sin(2 * np.pi * v.astype(np.float64)))):
        err = np.abs(got.astype(np.float64) - want)
        k = int(np.argmax(err))
        assert err.max() < 2.5e-7, f"worst at v={v[k]!r}: {got[k]!r} vs {want[k]!r}"


def test_exp2_bounded_within_4_ulp_on_its_domain():
    rng = np.random.default_rng(5)
    x = np.concatenate([rng.uniform(-126, 126, 200000), rng.uniform(-1, 1, 20000),
                        np.arange(-126, 127, dtype=np.float64), [-126.0, 126.0, 0.5, -0.5]]).astype(np.float32)
    got = _run(x)[3]
    err = _ulp_err(got, np.exp2(x.astype(np.float64)))
    k = int(np.argmax(err))
    assert err.max() <= 4.0, f"worst {err[k]:.2f} ulp at x={x[k]!r}"
