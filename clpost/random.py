"""numpy twin of ``kernels/random.cl``: the same counter-based hash, bit for bit.

Every random number in clpost is a pure function of (seed, frame, pixel, sample) — see
CONVENTIONS.md "Randomness" — so references reproduce a kernel's noise exactly and results do not
depend on the device or the work-group size. Hash: Wellons' ``lowbias32`` finaliser chained over
the counter words.
"""
from __future__ import annotations

import numpy as np

_M = np.uint32


def mix(x):
    x = np.asarray(x, dtype=np.uint32)
    with np.errstate(over="ignore"):
        x = x ^ (x >> _M(16))
        x = x * _M(0x7FEB352D)
        x = x ^ (x >> _M(15))
        x = x * _M(0x846CA68B)
        x = x ^ (x >> _M(16))
    return x


def hash4(seed, frame, a, b):
    u = lambda v: np.asarray(v).astype(np.uint32)  # noqa: E731 — wraps like C's uint
    h = mix(u(seed) ^ _M(0x9E3779B9))
    h = mix(h ^ u(frame))
    h = mix(h ^ u(a))
    return mix(h ^ u(b))


def uniform(h):
    """(0, 1) from the 24 high bits: the bin centre ``rnd_uniform`` rounds to float32, exact in
    float64 (the kernel's float32 rounds the upper half's centres to even, the top one to 1.0)."""
    return ((np.asarray(h, np.uint32) >> _M(8)).astype(np.float64) + 0.5) / 16777216.0


def poisson_inversion(mean, u):
    """Poisson(mean) by inversion, as ``rnd_poisson_inversion``: the smallest n with
    u ≤ F(n; mean), the same sequential search over the pmf (at most 128 steps), float64."""
    mean = np.asarray(mean, np.float64)
    u = np.asarray(u, np.float64)
    n = np.zeros(np.broadcast(mean, u).shape)
    prob = np.exp(-mean)
    cdf = prob.copy()
    active = u > cdf
    k = 0
    while active.any() and k < 128:
        k += 1
        prob = prob * mean / k
        cdf = cdf + prob
        n = np.where(active, k, n)
        active &= u > cdf
    return n


def normal(h1, h2):
    """Box-Muller as ``rnd_normal`` (float64 here; the kernel's float32 differs by ~1e-6)."""
    return np.sqrt(-2.0 * np.log(uniform(h1))) * np.cos(2.0 * np.pi * uniform(h2))


def normal_pair(h1, h2):
    """Both Box-Muller normals of one draw, as ``rnd_normal_pair``: (cosine branch — equal to
    :func:`normal` — and sine branch), independent standard normals."""
    rad = np.sqrt(-2.0 * np.log(uniform(h1)))
    u2 = 2.0 * np.pi * uniform(h2)
    return rad * np.cos(u2), rad * np.sin(u2)


POISSON_EXACT_MAX = 32.0
"""Where :func:`poisson` switches from exact inversion to the normal approximation (error of the
normal approximation to Poisson at mean 32: < 1 % in σ)."""


def poisson(mean, u, g):
    """Photon shot noise as ``rnd_poisson``: Poisson(mean) by inversion (uniform ``u``) for means
    ≤ :data:`POISSON_EXACT_MAX`, else ``max(round(mean + sqrt(mean)·g), 0)`` (standard normal
    ``g``), float64."""
    mean = np.asarray(mean, np.float64)
    return np.where(mean > POISSON_EXACT_MAX, np.maximum(np.round(mean + np.sqrt(mean) * g), 0.0),
                    poisson_inversion(np.minimum(mean, POISSON_EXACT_MAX), u))
