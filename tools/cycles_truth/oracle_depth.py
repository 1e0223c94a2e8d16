"""What a DoF depth rule's misfire on a lamp costs: clpost on a Cycles pinhole export as is, and with
the depth of each named lamp's (2r+1)² window set to the lamp's own depth (an oracle), scored
against the Cycles truth (PSNR/FLIP of the sRGB view, the lamps' disc area or in-focus halo).
Runs in clpost's venv (not the bpy one); docs/fidelity.md, "Held-out scenes".

    .venv/bin/python tools/cycles_truth/oracle_depth.py --data tests/data/cycles_heldout h_lamps lamp01,lamp05,lamp10
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent.parent
sys.path.insert(0, str(ROOT / "tools"))

import cycles_compare as cc  # noqa: E402
from clpost import fidelity as fd  # noqa: E402
from clpost.frame import Frame  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene")
    p.add_argument("lamps", help="comma-separated lamp names of the manifest")
    p.add_argument("--data", default=str(ROOT / "tests" / "data" / "cycles_heldout"))
    p.add_argument("--qualities", default="draft,preview,final")
    p.add_argument("--radius", type=int, default=1, help="window half-size r (px)")
    a = p.parse_args(argv)
    entry, frame, emit, truths = cc.load_scene(a.scene, Path(a.data))
    truth, truth_lamps = truths["dof"]
    names = a.lamps.split(",")
    depth = frame.depth.copy()
    r = a.radius
    for lamp in entry["lamps"]:
        if lamp["name"] in names:
            x, y = round(lamp["x_px"]), round(lamp["y_px"])
            depth[y - r:y + r + 1, x - r:x + r + 1] = lamp["depth_m"]
    oracle = Frame(color=frame.color, depth=depth, velocity=frame.velocity, alpha=frame.alpha)
    for q in a.qualities.split(","):
        for label, fr in (("as is", frame), ("oracle", oracle)):
            out = cc.run_clpost(fr, entry, "dof", q, 0)[0]
            lamps_out = out - cc.run_clpost(cc.without_lamps(fr, emit), entry, "dof", q, 0)[0]
            parts = []
            for lamp in entry["lamps"]:
                if lamp["name"] in names:
                    m = fd.emitter_metrics(out, truth, lamps_out, truth_lamps, lamp, entry["shot"], cc.WHITE)
                    parts.append(f"{lamp['name']} halo {m['halo_test']} vs {m['halo_truth']}" if m["in_focus"]
                                 else f"{lamp['name']} area {m['area_ratio']:.2f}")
            print(f"{a.scene} {q:8s} {label:7s} PSNR {fd.psnr_srgb(truth, out):.2f} "
                  f"FLIP {fd.flip_ldr(truth, out):.5f}  " + ", ".join(parts), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
