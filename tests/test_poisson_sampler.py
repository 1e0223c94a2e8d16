"""kernels/random.cl's Poisson sampler (sensor's and raw's shot noise): the 16-lane and one-lane
searches against clpost/random.py's float64 inversion (the same n from the same u), and the counts
of hashed uniforms against scipy.stats.poisson (chi-square)."""
import numpy as np
import pytest
from scipy import stats

cl = pytest.importorskip("pyopencl")

from clpost import random as rnd  # noqa: E402
from clpost.codegen import library, library_lanes16  # noqa: E402
from clpost.runtime import get_runtime  # noqa: E402

_SRC = library() + library_lanes16() + """
__kernel void pois(__global const float *mean, __global const float *u, __global float *out, const int n) {
    const int i = 16 * get_global_id(0);
    if (i + 16 > n) return;
    vstore16(rnd_poisson_inversion_w16(vload16(0, mean + i), vload16(0, u + i)), 0, out + i);
    for (int k = i; k < i + 16; ++k)
        out[n + k] = rnd_poisson_inversion(mean[k], u[k]);
}
"""


def _run(mean, u):
    rt = get_runtime()
    mean, u = (np.ascontiguousarray(a, np.float32) for a in (mean, u))
    assert mean.size % 16 == 0
    out = np.empty(2 * mean.size, np.float32)
    mf = cl.mem_flags
    bufs = [cl.Buffer(rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a) for a in (mean, u)]
    ob = cl.Buffer(rt.context, mf.WRITE_ONLY, out.nbytes)
    cl.Kernel(rt.program(_SRC, "pois"), "pois")(rt.queue, (mean.size // 16,), None, *bufs, ob,
                                                np.int32(mean.size))
    cl.enqueue_copy(rt.queue, out, ob)
    return out.reshape(2, -1)


def test_search_gives_the_float64_inversions_count():
    # every lane its own mean (0 to 32, and the bright lanes' 0), u from the hash as sensor draws it
    rng = np.random.default_rng(5)
    n = 16 * 20000
    mean = rng.uniform(0.0, 32.0, n).astype(np.float32)
    mean[rng.random(n) < 0.1] = 0.0
    u = rnd.uniform(rnd.hash4(3, 7, np.arange(n), 0)).astype(np.float32)
    got16, got1 = _run(mean, u)
    want = rnd.poisson_inversion(mean.astype(np.float64), u.astype(np.float64))
    np.testing.assert_array_equal(got16, got1)
    differ = got16 != want
    # float32 sums vs float64: only where u lies within rounding of F(n), off by one
    assert differ.mean() < 1e-4, f"{differ.sum()} of {n} differ"
    assert np.all(np.abs(got16 - want) <= 1)
    assert np.all(got16[mean == 0] == 0)


@pytest.mark.parametrize("lam", [0.7, 4.0, 13.5, 31.9])
def test_counts_follow_the_poisson_distribution(lam):
    n = 16 * 8192
    u = rnd.uniform(rnd.hash4(11, 2, np.arange(n), 4)).astype(np.float32)
    counts = _run(np.full(n, lam, np.float32), u)[0].astype(int)
    # chi-square over bins with >= 20 expected, the tails pooled
    k = np.arange(int(lam + 12 * np.sqrt(lam) + 12))
    expect = n * stats.poisson.pmf(k, lam)
    keep = expect >= 20
    lo, hi = k[keep][0], k[keep][-1]
    obs = np.array([np.sum(counts <= lo)] + [np.sum(counts == j) for j in range(lo + 1, hi)] + [np.sum(counts >= hi)])
    exp = n * np.array([stats.poisson.cdf(lo, lam)] + [stats.poisson.pmf(j, lam) for j in range(lo + 1, hi)]
                       + [stats.poisson.sf(hi - 1, lam)])
    chi2 = float(np.sum((obs - exp) ** 2 / exp))
    assert stats.chi2.sf(chi2, len(obs) - 1) > 1e-3, (chi2, len(obs))
    assert counts.mean() == pytest.approx(lam, rel=0.02) and counts.var() == pytest.approx(lam, rel=0.03)


def test_the_top_uniforms_give_the_extreme_quantile_not_the_step_limit():
    # the top 24-bit uniform rounds to 1.0f, and the float32 sum of the pmf may stop an ulp short of
    # it: a search that only stops where u <= F(n) runs to its 128-step limit there (a 128 e⁻ speck
    # in the shadows; how often: docs/benchmarks.md)
    mean = np.linspace(0.0, 32.0, 16 * 4000).astype(np.float32)
    want = rnd.poisson_inversion(mean.astype(np.float64), np.full(mean.size, 1.0 - 2.0 ** -25))
    for top in (1.0, 1.0 - 2.0 ** -24, 1.0 - 2.0 ** -23):
        for got in _run(mean, np.full(mean.size, top, np.float32)):
            assert np.all(got >= want - 8) and np.all(got <= want + 16), (top, float(np.max(got - want)))
