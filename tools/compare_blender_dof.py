"""Blender's compositor Defocus vs clpost's dof levels, both on the same pinhole EXR and both judged
against clpost's accumulation-buffer thin-lens reference of the demo scene.

    PYTHONPATH=. /tmp/venv/bin/python tools/compare_blender_dof.py \\
        --blender /tmp/bpyvenv/bin/python [--samples 128,64] [--repeats 3] [--blender-repeats 3,1] \\
        [--max-blur 64] [--work /tmp/blender_check] [--doc docs/benchmarks.md]

Per size (640×360, 1280×720): renders the reference and the pinhole frame
(:func:`clpost.dof_bench.run_dof_bench`, which also times clpost's levels with OpenCL events),
writes the pinhole as a clpost-native EXR (R, G, B, Z), runs ``tools/blender_defocus.py`` on it
in the bpy interpreter (a subprocess: bpy is not a clpost dependency), and scores Blender's
result with the same PSNR (linear) and FLIP (sRGB view) as clpost's rows. clpost's rows are also
timed by wall clock around ``Pipeline.run`` (upload + kernels + download), the fairer comparison
with Blender's wall time. Replaces the "Blender Defocus" section of ``--doc`` (or appends it)
and writes ``docs/dof_blender_compare.png`` (pinhole | Blender | clpost final | reference).
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from clpost.camera import Camera
from clpost.dof_bench import BENCH_CAMERA, VIEW_SCALE, flip_ldr, psnr_linear, run_dof_bench, srgb
from clpost.exr import write_frame
from clpost.frame import Frame
from clpost.pipeline import Pipeline
from clpost.runtime import get_runtime
from clpost.stages import QUALITIES

TOOL = Path(__file__).with_name("blender_defocus.py")
SECTION = "## dof: Blender compositor Defocus (the peer), same pinhole EXR, same reference"


def read_rgb_exr(path: Path) -> np.ndarray:
    import OpenEXR

    ch = OpenEXR.File(str(path), separate_channels=True).parts[0].channels
    return np.stack([ch[c].pixels for c in "RGB"], -1).astype(np.float32)


def wall_ms(pipe: Pipeline, frame: Frame, repeats: int) -> float:
    pipe.run(frame)  # warm-up (compile, allocate)
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        pipe.run(frame)
        ts.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(ts)


def crop_panel(images, labels, boxes, path: Path) -> None:
    """Side-by-side crops of linear images (sRGB view at VIEW_SCALE), one row per box, labelled."""
    from PIL import Image, ImageDraw

    gap, top = 4, 18
    rows = []
    for x0, y0, x1, y1 in boxes:
        rows.append([Image.fromarray((srgb(im[y0:y1, x0:x1] * VIEW_SCALE) * 255 + 0.5).astype(np.uint8))
                     for im in images])
    w = max(r[0].size[0] for r in rows)
    panel = Image.new("RGB", (len(images) * (w + gap) - gap, top + sum(r[0].size[1] + gap for r in rows)),
                      (255, 255, 255))
    draw = ImageDraw.Draw(panel)
    for i, lab in enumerate(labels):
        draw.text((i * (w + gap) + 4, 3), lab, fill=(0, 0, 0))
    y = top
    for r in rows:
        for i, t in enumerate(r):
            panel.paste(t, (i * (w + gap), y))
        y += r[0].size[1] + gap
    panel.save(path)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--blender", required=True, help="Python interpreter with bpy (e.g. /tmp/bpyvenv/bin/python)")
    p.add_argument("--samples", default="128,64", help="reference aperture samples per size")
    p.add_argument("--repeats", type=int, default=3, help="clpost repeats (after one warm-up)")
    p.add_argument("--blender-repeats", default="3,1", help="Blender repeats per size (after one warm-up)")
    p.add_argument("--max-blur", type=float, default=64.0, help="Defocus 'Max Blur' radius in px")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--work", default="/tmp/blender_check")
    p.add_argument("--doc", default="docs/benchmarks.md")
    p.add_argument("--png", default="docs/dof_blender_compare.png")
    p.add_argument("--crop", default="0.0,0.1,0.3,0.6;0.55,0.6,0.85,1.0",
                   help="crops of the 1280×720 frame for the PNG, fractions x0,y0,x1,y1, ';' between rows")
    a = p.parse_args(argv)
    work = Path(a.work)
    work.mkdir(parents=True, exist_ok=True)
    samples = tuple(int(s) for s in a.samples.split(","))
    bl_repeats = [int(s) for s in a.blender_repeats.split(",")]
    sizes = ((640, 360), (1280, 720))

    rows, _ = run_dof_bench(sizes=sizes, samples=samples, repeats=a.repeats, save_dir=str(work))
    camera = Camera(**BENCH_CAMERA)
    table, blender_info, images = [], None, {}
    for (w, h), reps in zip(sizes, bl_repeats):
        arrays = np.load(work / f"reference_{w}x{h}.npz")
        ref = arrays["ref"].astype(np.float64)
        pin = Frame(color=arrays["pinhole"], depth=arrays["depth"])
        exr_in, exr_out, js = work / f"pinhole_{w}x{h}.exr", work / f"blender_{w}x{h}.exr", work / f"blender_{w}x{h}.json"
        write_frame(exr_in, pin)
        cmd = [a.blender, str(TOOL), str(exr_in), str(exr_out), "--f-number", str(camera.f_number),
               "--focal-mm", str(camera.focal_length_mm), "--sensor-mm", str(camera.sensor_mm[0]),
               "--focus-m", str(camera.focus_distance_m), "--blades", str(camera.blades),
               "--rotation-deg", str(camera.blade_rotation_deg), "--angle-deg", str(camera.blade_rotation_deg),
               "--max-blur", str(a.max_blur), "--threads", str(a.threads), "--repeats", str(reps),
               "--json", str(js)]
        print(" ".join(cmd), flush=True)
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        info = json.loads(js.read_text())
        blender_info = info
        bl = read_rgb_exr(exr_out)
        if bl.shape != ref.shape:
            raise SystemExit(f"{exr_out}: Blender wrote {bl.shape}, expected {ref.shape}")
        table.append(dict(size=(w, h), name="Blender Defocus", ms=info["defocus_s"] * 1e3,
                          wall_ms=info["render_median_s"] * 1e3, psnr=psnr_linear(ref, bl), flip=flip_ldr(ref, bl)))
        print(f"{w}x{h} Blender: {table[-1]}", flush=True)
        for r in rows:
            if (r.width, r.height) != (w, h):
                continue
            wall = None
            if r.quality in QUALITIES:
                wall = wall_ms(Pipeline(camera, quality=r.quality, stages=["dof"]), pin, a.repeats)
            table.append(dict(size=(w, h), name=f"clpost {r.quality}", ms=r.ms, wall_ms=wall, psnr=r.psnr_db, flip=r.flip))
        images[(w, h)] = (arrays["pinhole"], bl, np.load(work / f"final_{w}x{h}.npy"), arrays["ref"])

    boxes = []
    for crop in a.crop.split(";"):
        fx0, fy0, fx1, fy1 = (float(s) for s in crop.split(","))
        boxes.append((int(fx0 * 1280), int(fy0 * 720), int(fx1 * 1280), int(fy1 * 720)))
    crop_panel(images[(1280, 720)], ["pinhole", "Blender Defocus", "clpost final", "reference"], boxes, Path(a.png))

    def fmt(v, spec, none="—"):
        return none if v is None else format(v, spec)

    lines = [SECTION, "",
             "Command: `PYTHONPATH=. /tmp/venv/bin/python tools/compare_blender_dof.py "
             + " ".join(sys.argv[1:] if argv is None else argv) + "`", "",
             f"Blender {blender_info['blender']} (`bpy` from PyPI, CPU compositor, full precision, "
             f"{blender_info['threads']} threads); clpost on {get_runtime().name}. Max Blur {a.max_blur:g} px.", "",
             "| size | method | ms/frame (median) | wall ms/frame (median) | PSNR linear (dB) | FLIP (sRGB, mean) |",
             "|---|---|---|---|---|---|"]
    for t in table:
        ms = "—" if t["name"] == "clpost pinhole" else f"{t['ms']:.1f}"
        lines.append(f"| {t['size'][0]}×{t['size'][1]} | {t['name']} | {ms} | {fmt(t['wall_ms'], '.1f')} | "
                     f"{t['psnr']:.2f} | {fmt(t['flip'], '.4f', 'n/a')} |")
    section = "\n".join(lines) + "\n"
    (work / "blender_section.md").write_text(section)
    print(section)
    doc = Path(a.doc)
    text = doc.read_text() if doc.exists() else "# Benchmarks\n"
    if SECTION in text:
        head, _, rest = text.partition(SECTION)
        nxt = rest.find("\n## ")
        text = head + section + (rest[nxt + 1:] if nxt >= 0 else "")
    else:
        text = text.rstrip("\n") + "\n\n" + section
    doc.write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
