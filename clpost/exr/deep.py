r"""Deep OpenEXR images flattened to one sample per pixel, front to back.

A deep pixel holds any number of samples, each with premultiplied colour and alpha at a depth Z
(OpenEXR, "Interpreting OpenEXR Deep Pixels", Hillman 2013). Flattening sorts a pixel's samples by
Z (then ``ZBack``) and composites them front to back with *over*:

.. math::

    C = \sum_i C_i \prod_{j<i} (1 - A_j), \qquad A = 1 - \prod_i (1 - A_i)

for every colour channel C (premultiplied, like the result), and Z of the front sample (the
flattened image's depth is where the first surface is); other channels take the front sample's
value too. Pixels without samples are empty: colour and alpha 0, Z ``+inf``.

Not modelled: volumetric samples (ZBack > Z) that overlap are not split at each other's ends
before compositing (the paper's step 2), so overlapping volumes composite in the order of their
fronts — exact for hard surfaces and for volumes that do not overlap.
"""
from __future__ import annotations

import numpy as np

COMPOSITED = ("R", "G", "B", "A")
"""Channels accumulated with *over* (the others take the front sample's value)."""


def _samples(plane: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """The samples of an object array of per-pixel arrays, concatenated in pixel order (float64)."""
    parts = [np.asarray(a, np.float64) for a, n in zip(plane.ravel(), counts) if n]
    return np.concatenate(parts) if parts else np.zeros(0)


def flatten(planes: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Flat float32 planes (H, W) from deep ones (object arrays of per-pixel sample arrays, as the
    OpenEXR bindings read them); see the module docstring."""
    names = list(planes)
    shape = planes[names[0]].shape
    counts = np.fromiter((0 if a is None else len(a) for a in planes[names[0]].ravel()), np.int64,
                         count=int(np.prod(shape)))
    pixel = np.repeat(np.arange(counts.size), counts)
    values = {n: _samples(planes[n], counts) for n in names}
    z = values.get("Z", np.zeros(pixel.size))
    zback = values.get("ZBack", z)
    order = np.lexsort((zback, z, pixel))  # by pixel, then front to back
    pixel = pixel[order]
    values = {n: v[order] for n, v in values.items()}
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    rank = np.arange(pixel.size) - start[pixel]  # 0 for each pixel's front sample
    alpha = np.clip(values.get("A", np.zeros(pixel.size)), 0.0, 1.0)
    # transmittance in front of each sample: Π_{j<i}(1 − A_j), one sample depth at a time
    trans = np.ones(pixel.size)
    seen = np.ones(counts.size)
    for k in range(int(counts.max(initial=0))):
        at = rank == k
        trans[at] = seen[pixel[at]]
        seen[pixel[at]] *= 1.0 - alpha[at]
    out = {}
    front = rank == 0
    for n, v in values.items():
        if n in COMPOSITED:
            flat = np.bincount(pixel, weights=v * trans, minlength=counts.size)
        else:
            flat = np.full(counts.size, np.inf if n in ("Z", "ZBack") else 0.0)
            flat[pixel[front]] = v[front]
        out[n] = flat.reshape(shape).astype(np.float32)
    return out
