"""Print the first-order ghosts of a lens against full traces (docs/flare.md's table).

    python tools/ghost_check.py [lens] [f-number] [field deg] [count]
"""
import math
import sys

from clpost.optics import get_lens
from clpost.optics import ghosts as gh


def rows(name="zeiss-planar-50-f1.4", n=8.0, field_deg=2.0, count=8, wavelength_nm=550.0):
    lens = get_lens(name)
    pres = lens.focused(3000.0, n)
    r = lens.stop_radius_mm(n)
    theta = math.radians(field_deg)
    direct = gh.traced_ghost(pres, None, theta, r, wavelength_nm)
    gs = sorted(gh.ghosts(pres, r, wavelength_nm), key=lambda g: -g.share / g.radius_mm ** 2)[:count]
    out = []
    for g in gs:
        t = gh.traced_ghost(pres, g.path, theta, r, wavelength_nm)
        out.append(dict(path=g.path, share=g.share, centre=g.centre_factor, centre_traced=t["x"] / direct["x"],
                        radius=g.radius_mm, radius_traced=t["radius"]))
    return out


if __name__ == "__main__":
    args = sys.argv[1:]
    kw = dict(zip(("name", "n", "field_deg", "count"), [args[0]] + [float(a) for a in args[1:3]] + [int(a) for a in args[3:4]])) if args else {}
    print("| surfaces (1-based) | ρ | centre / source, first order | traced | error | radius mm, first order | traced | error |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows(**kw):
        i, j = r["path"]
        print(f"| {i + 1}, {j + 1} | {r['share']:.2e} | {r['centre']:+.3f} | {r['centre_traced']:+.3f} | "
              f"{(r['centre'] - r['centre_traced']) / abs(r['centre_traced']) * 100:+.1f} % | {r['radius']:.3f} | "
              f"{r['radius_traced']:.3f} | {(r['radius'] - r['radius_traced']) / r['radius_traced'] * 100:+.0f} % |")
