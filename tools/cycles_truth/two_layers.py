"""What two layers give: clpost's DoF on the one-layer pinhole export against the same scene
rendered as two layers (``render.py``'s ``fg`` and ``bg`` kinds: the foreground objects over a
transparent film, the rest without them) and processed with the ``front_layer`` stage, each
scored against the Cycles truth. Runs in clpost's venv (not the bpy one); docs/fidelity.md,
"Two layers: the foreground rendered as its own layer".

    .venv/bin/python tools/cycles_truth/two_layers.py occluder
    .venv/bin/python tools/cycles_truth/two_layers.py h_fence --data tests/data/cycles_heldout

Reads the layers the manifest lists (``<data>/<scene>/fg.exr``, ``bg.exr``; ``--layers DIR``:
``DIR/<scene>_fg.exr`` and ``_bg.exr`` instead, e.g. fresh renders). Also printed: how well ``fg + (1 − α) bg`` reproduces
the one-layer pinhole (the two renders' own sampling noise).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent.parent
sys.path.insert(0, str(ROOT / "tools"))

import cycles_compare as cc  # noqa: E402
from clpost import fidelity as fd  # noqa: E402
from clpost.frame import Frame  # noqa: E402


def load_layers(scene: str, data: Path, entry: dict, layers: str | None) -> Frame:
    if not layers:
        return fd.cycles_layers(data, entry)
    return fd.cycles_layers(Path(layers), {"layers": {k: {"file": f"{scene}_{k}.exr"} for k in ("fg", "bg")}})


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene")
    p.add_argument("--data", default=str(ROOT / "tests" / "data" / "cycles"))
    p.add_argument("--layers", default=None, help="folder with <scene>_fg.exr and <scene>_bg.exr")
    p.add_argument("--qualities", default="draft,preview,final")
    p.add_argument("--png", default=None, help="write pinhole | truth | one layer | two layers (final) here")
    a = p.parse_args(argv)
    entry, frame, _, truths = cc.load_scene(a.scene, Path(a.data))
    truth = truths["dof"][0]
    layered = load_layers(a.scene, Path(a.data), entry, a.layers)
    f = layered.front
    over = f[..., :3] + (1 - f[..., 3:4]) * layered.color
    print(f"{a.scene}: front covers {int((f[..., 3] > 0).sum())} px; front over background vs the pinhole "
          f"PSNR {fd.psnr_srgb(frame.color[..., :3], over):.2f}")
    print(f"{'':8s} {'one layer (as exported)':>27s} {'two layers':>24s}")
    rows = {}
    for q in a.qualities.split(","):
        one = cc.run_clpost(frame, entry, "dof", q, 0)[0]
        pipe = fd.cycles_pipeline(entry, "dof", q, front=True)
        two = np.asarray(pipe.run(layered).color, np.float32)
        rows[q] = (one, two)
        print(f"{q:8s} PSNR {fd.psnr_srgb(truth, one):6.2f} FLIP {fd.flip_ldr(truth, one):.5f}    "
              f"PSNR {fd.psnr_srgb(truth, two):6.2f} FLIP {fd.flip_ldr(truth, two):.5f}", flush=True)
    floor = entry["truths"]["dof"]["noise_floor_psnr_srgb_db"]
    print(f"noise floor {floor:.2f} dB; the target for final: ≥ {floor - 4:.2f} dB, FLIP ≤ 0.03")
    if a.png and "final" in rows:
        one, two = rows["final"]
        cc.sheet([frame.color[..., :3], truth, one, two], ["pinhole", "Cycles", "one layer", "two layers"],
                 Path(a.png))
        print(f"wrote {a.png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
