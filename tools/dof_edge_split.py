r"""Measure splitting a blurred foreground's anti-aliased edge pixels into two layers (issue 16;
docs/fidelity.md, "Splitting the edge pixels into two layers") with the numpy reference only.

    PYTHONPATH=. .venv/bin/python tools/dof_edge_split.py --scenes occluder,thin [--data DIR] \
        [--qualities final] [--estimate mirror] [--own] [--wide] [--alpha unmix] [--min-px 2]

An anti-aliased edge pixel p carries the colour :math:`c = \alpha F + (1-\alpha) B` of a near and
a far surface but one point-sampled depth. The split gives the full-resolution gather two sources
at p (``gather_reference``'s ``split``): the far share :math:`1-\alpha` with the far surface's
colour B at the far CoC, the near share α with the rest, :math:`(c - (1-\alpha) B)/\alpha`
(clamped at 0), at the near CoC — so a rim darker than both surfaces stays with the near one.
An *edge pixel*: its 3×3 holds CoCs more than ``--min-px`` apart (split at the mid-CoC into a near
and a far layer). F and B:

* ``--estimate mean``: the means of p's 3×3 neighbours in each layer;
* ``--estimate mirror``: along the image axes (``--diag``: and diagonals), pairs of neighbours
  across p with a near pixel on one side and a far one on the other (F the near one, B the far
  one: the far surface continued through p), averaged over the pairs (``--best``: the pair whose
  colour line passes nearest to c). ``--own``: the far side must be p's own surface (CoC within
  ``--min-px``/2 of p's) and the near side nearer than p by ``--min-px`` (three layers: a pixel of
  an in-focus object between a blurred wire and the far wall is no mix of those two); ``--wide``:
  the near side's next pixel on the same line near too (a 1-px depth speckle is no silhouette);
  ``--solid``: no far neighbour of the near side's pixel q, across the pair's line, has q's
  luminance within 1 − ``FRINGE_STEP`` (a near depth sample whose colour continues into the far
  surface is a pane's speckle or a semi-transparent surface, not an opaque edge); ``--solid8``:
  any of q's 8 neighbours (with ``--solid``).

α: ``unmix`` (least squares on the line from B to F, clamped to [0, 1]) or ``geo`` (the expected
coverage of a straight edge between the last near and first far sample: ¾ for a near pixel, ¼ for
a far one); ``--floor``: at least the α that keeps the near colour non-negative. ``--far-only``:
split only pixels of the far layer; ``--drop-near``: their near share is dropped (a colour
rewrite of the input, no second source). Prints PSNR sRGB / FLIP-LDR of the reference against the
Cycles truth without and with the split (the reference equals the kernels' output to ~1e-4, so
the baseline column is the docs' table). The split applies to the full-resolution gather only
(draft and preview gather at half resolution and are unchanged).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import cycles_compare as cc  # noqa: E402

from clpost import fidelity as fd  # noqa: E402
from clpost.stages import dof  # noqa: E402


def _shift(a: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """a at (y + dy, x + dx), edge-clamped (dof's own 1-D shift along each axis)."""
    return dof._shift_clamped(dof._shift_clamped(a, dy, 0), dx, 1)


def edge_split(color: np.ndarray, coc: np.ndarray, o) -> tuple:
    """``(D, O, b, r_o)`` of :func:`clpost.stages.dof.gather_reference`'s ``split`` (module docstring)."""
    c = np.asarray(color, np.float64)[..., :3]
    n = dof._neighbourhood(coc)
    lo, hi = np.minimum.reduce(n), np.maximum.reduce(n)
    edge = (hi - lo) > o.min_px
    mid = 0.5 * (lo + hi)
    own_near = coc < mid
    Fs, Bs = np.zeros_like(c), np.zeros_like(c)
    Fn, Bn = np.zeros(coc.shape), np.zeros(coc.shape)
    if o.estimate == "mean":
        offs = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0)]
        for dy, dx in offs:
            isn = _shift(coc, dy, dx) < mid
            cq = _shift(c, dy, dx)
            Fs += np.where(isn[..., None], cq, 0); Fn += isn
            Bs += np.where(isn[..., None], 0, cq); Bn += ~isn
    else:
        best = np.full(coc.shape, np.inf)
        for dy, dx in [(1, 0), (0, 1)] + ([(1, 1), (1, -1)] if o.diag else []):
            ca, ra, cb, rb = _shift(c, dy, dx), _shift(coc, dy, dx), _shift(c, -dy, -dx), _shift(coc, -dy, -dx)
            if o.own:
                m1 = (ra < coc - o.min_px) & (np.abs(rb - coc) <= 0.5 * o.min_px)
                m2 = (rb < coc - o.min_px) & (np.abs(ra - coc) <= 0.5 * o.min_px)
            else:
                m1, m2 = (ra < mid) & (rb >= mid), (rb < mid) & (ra >= mid)
            if o.wide:
                m1 = m1 & (_shift(coc, 2 * dy, 2 * dx) < mid)
                m2 = m2 & (_shift(coc, -2 * dy, -2 * dx) < mid)
            if o.solid:
                # the near side's pixel q: a far neighbour of q across the edge's direction with q's
                # colour (luma within 1 - FRINGE_STEP) makes q a depth speckle, no opaque edge
                y_ = c @ dof.luma_weights()
                for sg, m in ((1, m1), (-1, m2)):
                    qy, qx = sg * dy, sg * dx
                    yq = _shift(y_, qy, qx)
                    twin = np.zeros(coc.shape, bool)
                    for py, px in (((dx, dy), (-dx, -dy)) if not o.solid8 else
                                   [(i, j) for i in (-1, 0, 1) for j in (-1, 0, 1) if (i, j) != (0, 0)]):
                        rn, yn = _shift(coc, qy + py, qx + px), _shift(y_, qy + py, qx + px)
                        twin |= (rn >= mid) & (np.abs(yn - yq) <= (1 - dof.FRINGE_STEP) * np.maximum(yq, yn))
                    if sg == 1:
                        m1 = m1 & ~twin
                    else:
                        m2 = m2 & ~twin
            Fq, Bq = np.where(m1[..., None], ca, cb), np.where(m1[..., None], cb, ca)
            if o.best:
                dq = Fq - Bq
                dn2 = np.maximum(np.sum(dq * dq, -1), 1e-12)
                aq = np.clip(np.sum((c - Bq) * dq, -1) / dn2, 0, 1)
                res = np.sum((c - Bq - aq[..., None] * dq) ** 2, -1) / dn2
                take = (m1 | m2) & (res < best)
                best = np.where(take, res, best)
                Fs, Bs = np.where(take[..., None], Fq, Fs), np.where(take[..., None], Bq, Bs)
                Fn, Bn = np.where(take, 1, Fn), np.where(take, 1, Bn)
            else:
                m = (m1 | m2)[..., None]
                Fs += np.where(m, Fq, 0); Bs += np.where(m, Bq, 0)
                Fn += m1 | m2; Bn += m1 | m2
    Fm, Bm = Fs / np.maximum(Fn, 1)[..., None], Bs / np.maximum(Bn, 1)[..., None]
    dF = Fm - Bm
    den = np.sum(dF * dF, -1)
    au = np.where(den > 1e-12, np.sum((c - Bm) * dF, -1) / np.maximum(den, 1e-12), np.where(own_near, 1.0, 0.0))
    a = np.where(own_near, 0.75, 0.25) if o.alpha == "geo" else np.clip(au, 0.0, 1.0)
    if o.floor:
        need = np.max(np.where(Bm > 1e-6, 1.0 - c / np.maximum(Bm, 1e-6), 0.0), -1)
        a = np.maximum(a, np.clip(need, 0.0, 1.0))
    edge = edge & (Fn > 0) & (Bn > 0)
    if o.far_only:
        edge = edge & ~own_near
    a = np.where(edge, a, np.where(own_near, 1.0, 0.0))
    near_c = np.where((a > 1e-6)[..., None],
                      np.maximum(c - (1 - a)[..., None] * Bm, 0.0) / np.maximum(a, 1e-6)[..., None], c)
    far_c = np.where(((a > 1e-6) & (a < 1 - 1e-6))[..., None], Bm, c)
    D = np.where(edge[..., None], np.where(own_near[..., None], near_c, far_c), c)
    O = np.where(own_near[..., None], far_c, near_c)
    b = np.where(edge, np.where(own_near, 1.0 - a, a), 0.0)
    if o.drop_near:
        b = np.zeros_like(b)
    return D, O, b, np.where(own_near, hi, lo)


def run(entry, frame, quality: str, opts) -> np.ndarray:
    """The reference pipeline's image, the full-resolution gather split by ``opts`` (None: not)."""
    orig = dof.gather_reference

    def split_gather(color, coc, *args, **kw):
        if opts is not None and kw.get("lights", True):  # the full-resolution call (lights on)
            kw["split"] = edge_split(color, coc, opts)
        return orig(color, coc, *args, **kw)

    dof.gather_reference = split_gather
    try:
        return np.asarray(fd.cycles_pipeline(entry, "dof", quality).reference(frame))[..., :3]
    finally:
        dof.gather_reference = orig


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", required=True)
    p.add_argument("--data", default=str(cc.DATA))
    p.add_argument("--qualities", default="final")
    p.add_argument("--estimate", choices=("mean", "mirror"), default="mirror")
    p.add_argument("--alpha", choices=("unmix", "geo"), default="unmix")
    p.add_argument("--min-px", type=float, default=2.0)
    for f in ("own", "wide", "solid", "solid8", "diag", "best", "floor", "far-only", "drop-near"):
        p.add_argument(f"--{f}", action="store_true")
    o = p.parse_args(argv)
    print("scene quality: PSNR / FLIP without the split -> with it")
    for name in o.scenes.split(","):
        entry, frame, _, truths = cc.load_scene(name, Path(o.data))
        truth = truths["dof"][0]
        for q in o.qualities.split(","):
            a, b = run(entry, frame, q, None), run(entry, frame, q, o)
            print(f"{name} {q}: {fd.psnr_srgb(truth, a):.2f} / {fd.flip_ldr(truth, a):.5f} -> "
                  f"{fd.psnr_srgb(truth, b):.2f} / {fd.flip_ldr(truth, b):.5f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
