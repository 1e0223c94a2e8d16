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
import math
import sys

import numpy as np

from clpost.optics import get_lens
from clpost.optics import ghosts as gh


def rows(name="zeiss-planar-50-f1.4", n=8.0, field_deg=2.0, count=8, wavelength_nm=550.0):
    lens = get_lens(name)
    pres = lens.focused(3000.0, n)
    r = lens.stop_radius_mm(n)
    theta = math.radians(field_deg)
    direct = gh.traced_ghost(pres, None, theta, r, wavelength_nm, clip=True)
    fit = gh.fit_ghosts(pres, r, wavelength_nm)
    i0, i1, f = gh.fit_weights(fit["direct_mm"], direct["x"])
    index = {tuple(p): k for k, p in enumerate(fit["paths"])}
    gs = sorted(gh.ghosts(pres, r, wavelength_nm), key=lambda g: -g.share / g.radius_mm ** 2)[:count]
    out = []
    for g in gs:
        t = gh.traced_ghost(pres, g.path, theta, r, wavelength_nm, clip=True)
        refl = gh.surface_reflectance(pres, g.path[0], wavelength_nm) * gh.surface_reflectance(pres, g.path[1], wavelength_nm)
        k = index[g.path]

        def at(a):
            v0, v1 = a[k, i0], a[k, i1]
            v0, v1 = (v1 if np.isnan(v0) else v0), (v0 if np.isnan(v1) else v1)
            return (1 - f) * v0 + f * v1

        out.append(dict(path=g.path, share=g.share, share_fit=at(fit["share"]),
                        share_traced=refl * t["fraction"] / direct["fraction"],
                        centre=g.centre_factor, centre_fit=at(fit["centre"]), centre_traced=t["x"] / direct["x"],
                        radius=g.radius_mm, radius_fit=at(fit["radius_mm"]), radius_traced=t["radius"]))
    return out


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
