"""The checkerboard calibration check of the distortion stage (Lambers, Sommerhoff & Kolb): the
report of :mod:`clpost.calib_check.checkerboard` per parameter set, as in
docs/distortion_calibration.md. Needs OpenCV (``pip install '.[test]'``).

    PYTHONPATH=. python tools/distortion_calibration.py --views 17 --size 800x600 --png /tmp/distortion_check
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from clpost.calib_check.checkerboard import (BOARD_BLUR, CALIB_FLAGS_DOC, DETECTORS, PARAMS, SUBPIX_WINDOW,
                                             WHAT_IF, board_points, calibrate, calibrate_points, compare,
                                             conditioning_floor, detection_error, parameter_sets, render_views,
                                             resample_what_if, true_corners, undistort_roundtrip)
from clpost.calibration import OpenCVModel, inverse_residual_px, required_render

def _cells(rows: dict, floor: dict | None) -> list[str]:
    out = []
    for n in PARAMS:
        t, _, err = rows[n]
        if t:
            cell = f"{100 * err:.3f} %" + (f" ({100 * floor[n]:.2f} %)" if floor else "")
            out.append(f"**{cell}**" if err >= 0.01 else cell)
        else:
            out.append(f"{err:.1e} abs" + (f" ({floor[n]:.0e})" if floor else ""))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--views", type=int, default=17)
    ap.add_argument("--size", default="800x600")
    ap.add_argument("--blur", type=float, default=BOARD_BLUR, help="board anti-aliasing σ in px (0: box filter)")
    ap.add_argument("--detector", choices=DETECTORS, default="fit")
    ap.add_argument("--what-if", default="spline3", help=f"comma list of numpy resamplers from {WHAT_IF} ('' for none)")
    ap.add_argument("--png", default=None, help="directory for PNGs of the first views")
    args = ap.parse_args()
    size = tuple(int(t) for t in args.size.split("x"))
    other = [d for d in DETECTORS if d != args.detector][0]
    what_if = [w for w in args.what_if.split(",") if w]
    print(f"calibrateCamera flags: {CALIB_FLAGS_DOC}; detector {args.detector} (cornerSubPix window {SUBPIX_WINDOW} "
          f"first); board blur σ = {args.blur} px")
    table = []
    for name, model in parameter_sets(size).items():
        t0 = time.perf_counter()
        raw, out = render_views(model, args.views, blur=args.blur)
        spec = required_render(model)
        est, used, rms = calibrate(out, size, args.detector)
        print(f"\n{name}: {used}/{args.views} views detected, reprojection RMS {rms:.4f} px, "
              f"render {spec.width}x{spec.height} (f={spec.f:.1f}) for {size[0]}x{size[1]}, {time.perf_counter() - t0:.1f} s")
        de = detection_error(model, out, detector=args.detector)
        sigma = float(np.sqrt(np.mean(de**2)))
        pin = OpenCVModel(spec.width, spec.height, spec.f, spec.f, spec.cx, spec.cy)
        raw_err = {d: float(np.sqrt(np.mean(detection_error(model, raw, pin, d) ** 2))) for d in DETECTORS}
        print("  the same detectors on the undistorted renders (no stage): "
              + ", ".join(f"{d} RMS {e:.4f} px" for d, e in raw_err.items()))
        exact, _ = calibrate_points([board_points()] * args.views, [true_corners(model, v) for v in range(args.views)], size)
        exact_max = max(r[2] for r in compare(model, exact).values())
        floor = conditioning_floor(model, args.views, sigma)
        print(f"  detected − true corners: {len(de)} corners, mean ({de[:, 0].mean():+.4f}, {de[:, 1].mean():+.4f}) px, "
              f"RMS {sigma:.4f} px per axis, p99 |e| {np.percentile(np.abs(de), 99):.3f} px; from the exact true "
              f"corners every parameter is recovered to {exact_max:.1e}")
        print(f"  {'param':<6}{'true':>12}{'estimated':>14}{'error':>12}{'floor':>11}   (floor: true corners + N(0, {sigma:.4f} px), RMS of 8 draws)")
        for n, (t, e, err) in compare(model, est).items():
            f = 100 * floor[n] if t else floor[n]
            print(f"  {n:<6}{t:>12.6g}{e:>14.6g}{err * (100 if t else 1):>11.4g}{'%' if t else ' abs'}{f:>10.3g}{'%' if t else ''}")
        table.append((name, f"stage, {args.detector}", used, rms, sigma, raw_err[args.detector], compare(model, est), floor))
        est2, used2, rms2 = calibrate(out, size, other)
        sigma2 = float(np.sqrt(np.mean(detection_error(model, out, detector=other) ** 2)))
        table.append((name, f"stage, {other}", used2, rms2, sigma2, raw_err[other], compare(model, est2), None))
        for kind in what_if:
            alt = resample_what_if(model, raw, kind)
            est3, used3, rms3 = calibrate(alt, size, args.detector)
            sigma3 = float(np.sqrt(np.mean(detection_error(model, alt, detector=args.detector) ** 2)))
            table.append((name, f"what-if {kind}, {args.detector}", used3, rms3, sigma3, raw_err[args.detector],
                          compare(model, est3), None))
            print(f"  what-if {kind}: corner RMS {sigma3:.4f} px, "
                  + ", ".join(f"{n} {100 * r[2]:.3f} %" for n, r in compare(model, est3).items() if r[0]))
        for meth in ("newton", "heikkila"):
            r = inverse_residual_px(model, meth)
            print(f"  inverse {meth:<9} max {r['max_px']:.3g} px at {r['argmax_xy']}, RMS {r['rms_px']:.3g} px")
        if args.png:
            from pathlib import Path

            from clpost.atomic import write_png

            d = Path(args.png)
            for k in range(2):
                write_png(d / f"board_{name}_{k}_distorted.png", out[k].color / out[k].color.max())
                write_png(d / f"board_{name}_{k}_render.png", raw[k].color / raw[k].color.max())
    print("\n| set | resampling, detector | views | RMS reproj. (px) | corner err. RMS (px) | on the undistorted render | "
          + " | ".join(PARAMS) + " |")
    print("|---|---|---|---|---|---|" + "---|" * len(PARAMS))
    for name, what, used, rms, sigma, raw_e, rows, floor in table:
        print(f"| {name} | {what} | {used}/{args.views} | {rms:.4f} | {sigma:.4f} | {raw_e:.4f} | "
              + " | ".join(_cells(rows, floor)) + " |")
    rt = undistort_roundtrip(parameter_sets(size)["barrel"])
    print(f"\ndistort → cv2.undistort vs direct render (barrel, fy=fx): mean |e| {rt['mean_abs_rel_white']:.4f}, "
          f"median {rt['median_abs_rel_white']:.4f}, p99 {rt['p99_abs_rel_white']:.4f} of white over {rt['pixels']} px")


if __name__ == "__main__":
    main()
