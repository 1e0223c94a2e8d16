"""Print a lens's ghosts, first order and as the stage draws them (fitted from traces), against
dense full traces (docs/flare.md's tables).

    python tools/ghost_check.py [lens] [f-number] [field deg] [count]

Reference: a parallel beam of 161 × 161 rays filling the first surface at the field angle, every
element's clear aperture clipping (the real lens), through :func:`clpost.optics.ghosts.trace_path`:
centroid / the direct image's centroid, √2 × RMS radius, and the share
R_i R_j × (rays arriving on the ghost path / rays arriving directly). The fit
(:func:`clpost.optics.ghosts.fit_ghosts`, a separate pair of grids (~570 rays aimed at the stop, ~570 over the rest of the first surface) per angle on the grid
FIT_FIELD_DEG) is interpolated at the field angle as the stage does (:func:`fit_weights`).
"""
import sys

import numpy as np

from clpost.optics import ghosts as gh


def rows(*args, **kw):
    return gh.check_rows(*args, **kw)


def _err(a, ref):
    return "–" if not np.isfinite(a) or not np.isfinite(ref) or ref == 0 else f"{(a - ref) / abs(ref) * 100:+.0f} %"


if __name__ == "__main__":
    args = sys.argv[1:]
    kw = dict(zip(("name", "n", "field_deg", "count"), [args[0]] + [float(a) for a in args[1:3]] + [int(a) for a in args[3:4]])) if args else {}
    rs = rows(**kw)
    print("| surfaces (1-based) | ρ traced | error: first order / fit | centre / source, traced | error: first order / fit "
          "| radius mm, traced | error: first order / fit |")
    print("|---|---|---|---|---|---|---|")
    for r in rs:
        i, j = r["path"]
        print(f"| {i + 1}, {j + 1} | {r['share_traced']:.2e} | {_err(r['share'], r['share_traced'])} / {_err(r['share_fit'], r['share_traced'])} "
              f"| {r['centre_traced']:+.3f} | {_err(r['centre'], r['centre_traced'])} / {_err(r['centre_fit'], r['centre_traced'])} "
              f"| {r['radius_traced']:.3f} | {_err(r['radius'], r['radius_traced'])} / {_err(r['radius_fit'], r['radius_traced'])} |")
    tot = [sum(r[k] for r in rs) for k in ("share", "share_fit", "share_traced")]
    print(f"\nΣρ of these {len(rs)}: first order {tot[0]:.3e} ({tot[0] / tot[2]:.2f} × traced), fit {tot[1]:.3e} "
          f"({tot[1] / tot[2]:.2f} × traced), traced {tot[2]:.3e}")
