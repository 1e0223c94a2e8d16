"""clpost (every quality), Blender's compositor Defocus and Vector Blur, all on the same Cycles
pinhole EXRs, scored against Cycles' own thin-lens / motion-blur truths (tests/data/cycles/);
writes the tables of docs/fidelity.md.

    .venv/bin/python tools/cycles_compare.py [--blender /work/bpyvenv/bin/python] [--scenes emitters,thin]
        [--repeats 3] [--work /tmp/cycles/compare] [--doc docs/fidelity.md] [--sheets /tmp/cycles]

Per scene and truth (``dof``, ``motion``, ``dofmotion``): reads ``pinhole.exr`` the way
``clpost process`` does (:func:`clpost.exr.read_frame`, Blender layout), builds the camera that
images like the Blender camera (:func:`clpost.fidelity.cycles_camera`), runs
``Pipeline(camera, quality, stages)`` (one warm-up, then ``--repeats``; "ms" is the median of the
stages' OpenCL event times, "wall" of ``Pipeline.run``), and runs the peers in the bpy
interpreter as subprocesses (bpy is not a clpost dependency): ``tools/blender_defocus.py`` on the
same frame written in clpost's native layout (Max Blur = the frame's largest CoC radius, + 2 px)
and ``tools/blender_vector_blur.py`` on the pinhole EXR itself. Scores: PSNR of the sRGB views and
LDR-FLIP (:mod:`clpost.fidelity`), for motion also inside the box around moving pixels, and the
per-emitter metrics. A scene stored also as two layers (manifest ``layers``: ``fg.exr``, ``bg.exr``)
gets rows "clpost Q, two layers": its background with the foreground as ``Frame.front`` through
the same pipeline plus the front_layer stage (docs/fidelity.md, "Two layers"). Without
``--blender`` the peers' rows are left out. Results also go to
``--work``/results.json (the numbers tests/test_cycles_fidelity.py's floors were set from).
"""
from __future__ import annotations

import argparse
import json
import math
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from clpost import fidelity as fd
from clpost.exr import read_frame, write_frame
from clpost.frame import Frame
from clpost.stages import QUALITIES

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "tests" / "data" / "cycles"
STAGES = fd.CYCLES_STAGES
WHITE = 0.6  # tools/cycles_truth/scenes.py WHITE: sunlit diffuse white, the halo level's unit
BEGIN, END = "<!-- cycles_compare: begin -->", "<!-- cycles_compare: end -->"


read_rgb = fd.read_rgb


def load_scene(name: str, data: Path = DATA):
    """(manifest entry, pinhole Frame, pinhole Emit pass, {kind: (truth, truth's lamps alone)})."""
    man = json.loads((data / "manifest.json").read_text())
    entry = man["scenes"][name]
    pin = data / entry["pinhole"]["file"]
    frame = read_frame(pin)
    emit = read_rgb(pin, "Emission.")
    truths = {k: (read_rgb(data / t["file"]), read_rgb(data / t["file"], "emit.")) for k, t in entry["truths"].items()}
    return entry, frame, emit, truths


without_lamps = fd.without_lamps


def run_clpost(frame: Frame, entry: dict, kind: str, quality: str, repeats: int):
    """clpost's result (and median event / wall ms over ``repeats``); a frame with a front layer runs
    with the front_layer stage (its time counted)."""
    front = frame.front is not None
    pipe = fd.cycles_pipeline(entry, kind, quality, front=front)
    stages = STAGES[kind] + (["front_layer"] if front else [])
    out = pipe.run(frame).color
    events, walls = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = pipe.run(frame).color
        walls.append((time.perf_counter() - t0) * 1e3)
        events.append(sum(pipe.last_timings.get(s, 0.0) for s in stages))
    if not repeats:
        return np.asarray(out[..., :3], np.float32), None, None
    return np.asarray(out[..., :3], np.float32), statistics.median(events), statistics.median(walls)


def max_coc_radius(frame: Frame, shot: dict, width: int) -> float:
    d = frame.depth[np.isfinite(frame.depth)]
    c = fd.coc_px(np.array([d.min(), d.max(), 1e10]), shot["focus_m"], shot["focal_mm"], shot["f_number"],
                  shot["sensor_mm"], width)
    return float(c.max()) / 2


def run_defocus(blender: str, frame: Frame, entry: dict, work: Path, name: str, threads: int, repeats: int = 1):
    shot = entry["shot"]
    w, _ = entry["size"]
    exr_in, exr_out, js = work / f"{name}_native.exr", work / f"{name}_defocus.exr", work / f"{name}_defocus.json"
    write_frame(exr_in, Frame(color=frame.color[..., :3], depth=frame.depth))
    mb = math.ceil(max_coc_radius(frame, shot, w)) + 2
    cmd = [blender, str(ROOT / "tools" / "blender_defocus.py"), str(exr_in), str(exr_out),
           "--f-number", str(shot["f_number"]), "--focal-mm", str(shot["focal_mm"]),
           "--sensor-mm", str(shot["sensor_mm"]), "--focus-m", str(shot["focus_m"]), "--blades", str(shot["blades"]),
           "--rotation-deg", str(shot["rotation_deg"]), "--angle-deg", str(shot["rotation_deg"]),
           "--max-blur", str(mb), "--threads", str(threads), "--repeats", str(repeats), "--json", str(js)]
    print(" ".join(cmd), flush=True)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    info = json.loads(js.read_text())
    return read_rgb(exr_out), info["defocus_s"] * 1e3, info["render_median_s"] * 1e3, mb


def run_vector_blur(blender: str, data: Path, entry: dict, work: Path, name: str, threads: int, repeats: int):
    exr_out, js = work / f"{name}_vecblur.exr", work / f"{name}_vecblur.json"
    cmd = [blender, str(ROOT / "tools" / "blender_vector_blur.py"), str(data / entry["pinhole"]["file"]),
           str(exr_out), "--shutter", str(entry["shot"]["shutter_frames"]), "--threads", str(threads),
           "--repeats", str(repeats), "--json", str(js)]
    print(" ".join(cmd), flush=True)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    info = json.loads(js.read_text())
    return read_rgb(exr_out), info["vector_blur_s"] * 1e3, info["render_median_s"] * 1e3


def score(img, truth, entry, kind, frame, lamps=None):
    """Image scores; ``lamps`` = (result's lamps alone, truth's lamps alone) adds the emitter metrics."""
    row = {"psnr": fd.psnr_srgb(truth, img), "flip": fd.flip_ldr(truth, img)}
    if kind != "dof":
        box = fd.motion_box(frame.velocity, entry["shot"]["shutter_frames"])
        if box is not None:
            y0, y1, x0, x1 = box
            row["box"] = [int(v) for v in box]
            row["psnr_moving"] = fd.psnr_srgb(truth[y0:y1, x0:x1], img[y0:y1, x0:x1])
            row["flip_moving"] = fd.flip_ldr(truth[y0:y1, x0:x1], img[y0:y1, x0:x1])
    if lamps is not None:
        row["lamps"] = [fd.emitter_metrics(img, truth, lamps[0], lamps[1], lamp, entry["shot"], WHITE)
                        for lamp in entry["lamps"]]
    return row


def sheet(panels, labels, path: Path, scale: int = 1) -> None:
    """Side-by-side sRGB views, labelled (pinhole | truth | clpost final | peer)."""
    from PIL import Image, ImageDraw

    ims = [Image.fromarray((fd.srgb_view(p) * 255 + 0.5).astype(np.uint8)) for p in panels]
    w, h = ims[0].size
    gap, top = 4, 16
    out = Image.new("RGB", (len(ims) * (w + gap) - gap, h + top), (255, 255, 255))
    draw = ImageDraw.Draw(out)
    for i, (im, lab) in enumerate(zip(ims, labels)):
        out.paste(im, (i * (w + gap), top))
        draw.text((i * (w + gap) + 3, 2), lab, fill=(0, 0, 0))
    if scale != 1:
        out = out.resize((out.size[0] * scale, out.size[1] * scale), Image.NEAREST)
    out.save(path)


def lamp_summary(lamps):
    """(worst |area ratio − 1|, area ratios range, halo test/truth pairs, energy ratio range)."""
    areas = [l_["area_ratio"] for l_ in lamps if l_.get("area_ratio") is not None]
    halos = [(l_["halo_test"], l_["halo_truth"]) for l_ in lamps if l_["in_focus"]]
    energy = [l_["energy_ratio"] for l_ in lamps if l_["energy_ratio"] is not None]
    return areas, halos, energy


def fmt(v, spec):
    return "—" if v is None else format(v, spec)


def tables(results: dict, manifest: dict) -> str:
    lines = ["| scene | truth | floor dB | image | ms | wall ms | PSNR sRGB | FLIP-LDR | PSNR moving | FLIP moving |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for scene, kinds in results.items():
        for kind, rows in kinds.items():
            floor = manifest["scenes"][scene]["truths"][kind]["noise_floor_psnr_srgb_db"]
            for name, r in rows.items():
                lines.append(f"| {scene} | {kind} | {floor:.1f} | {name} | {fmt(r.get('ms'), '.1f')} | "
                             f"{fmt(r.get('wall_ms'), '.0f')} | {r['psnr']:.2f} | {fmt(r['flip'], '.5f')} | "
                             f"{fmt(r.get('psnr_moving'), '.2f')} | {fmt(r.get('flip_moving'), '.5f')} |")
    lines += ["", "Emitters (DoF truths; target: area ratio within 0.9–1.1, in-focus halo ≤ 2× Cycles', "
              "energy ratio within 0.97–1.03):", "",
              "| scene | image | disc area ratio (min…max) | in-focus halo px, image vs Cycles | energy ratio (min…max) |",
              "|---|---|---|---|---|"]
    for scene, kinds in results.items():
        for name, r in kinds.get("dof", {}).items():
            if "lamps" not in r:
                continue
            areas, halos, energy = lamp_summary(r["lamps"])
            a = f"{min(areas):.2f}…{max(areas):.2f}" if areas else "—"
            hl = ", ".join(f"{t} vs {c}" for t, c in halos) or "—"
            lines.append(f"| {scene} | {name} | {a} | {hl} | {min(energy):.3f}…{max(energy):.3f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--blender", default=None, help="Python with bpy for the Blender peers (omit: clpost only)")
    p.add_argument("--scenes", default=None, help="comma-separated (default: every scene in the manifest)")
    p.add_argument("--qualities", default=",".join(QUALITIES))
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--data", default=str(DATA))
    p.add_argument("--work", default="/tmp/cycles/compare")
    p.add_argument("--sheets", default="/tmp/cycles", help="contact sheets go here")
    p.add_argument("--doc", default=str(ROOT / "docs" / "fidelity.md"), help="'' to skip")
    p.add_argument("--merge", action="store_true",
                   help="keep the other scenes' results already in --work/results.json (one table for all), "
                        "and, without --blender, the peers' rows of the scenes run now")
    p.add_argument("--figure", default=str(ROOT / "docs" / "figures" / "cycles_emitters.png"))
    a = p.parse_args(argv)
    data, work, sheets = Path(a.data), Path(a.work), Path(a.sheets)
    work.mkdir(parents=True, exist_ok=True)
    sheets.mkdir(parents=True, exist_ok=True)
    manifest = json.loads((data / "manifest.json").read_text())
    names = a.scenes.split(",") if a.scenes else list(manifest["scenes"])
    results = {}
    if a.merge and (work / "results.json").exists():
        results = json.loads((work / "results.json").read_text())
    for name in names:
        entry, frame, emit, truths = load_scene(name, data)
        pinhole = frame.color[..., :3]
        dark = without_lamps(frame, emit)
        earlier = results.get(name, {}) if a.merge else {}
        results[name] = {}
        for kind, (truth, truth_lamps) in truths.items():
            with_lamps = kind == "dof" and bool(entry["lamps"])
            rows = {"pinhole input": score(pinhole, truth, entry, kind, frame, (emit, truth_lamps) if with_lamps else None)}
            peer = None
            if a.blender and kind == "dof":
                peer, ms, wall, mb = run_defocus(a.blender, frame, entry, work, name, a.threads, a.repeats)
                lamps = None
                if with_lamps:
                    peer_dark = run_defocus(a.blender, dark, entry, work, name + "_dark", a.threads)[0]
                    lamps = (peer - peer_dark, truth_lamps)
                rows[f"Blender Defocus (Max Blur {mb})"] = dict(score(peer, truth, entry, kind, frame, lamps),
                                                               ms=ms, wall_ms=wall)
            if a.blender and kind == "motion":
                peer, ms, wall = run_vector_blur(a.blender, data, entry, work, name, a.threads, a.repeats)
                rows["Blender Vector Blur"] = dict(score(peer, truth, entry, kind, frame), ms=ms, wall_ms=wall)
            final = None
            inputs = [("", frame, dark)]
            if kind == "dof" and "layers" in entry:  # the same export as two layers (front_layer)
                layered = fd.cycles_layers(data, entry)
                bg_emit = read_rgb(data / entry["layers"]["bg"]["file"], "Emission.")
                inputs.append((", two layers", layered, without_lamps(layered, bg_emit)))
            for label, src, src_dark in inputs:
                for q in a.qualities.split(","):
                    out, ms, wall = run_clpost(src, entry, kind, q, a.repeats)
                    lamps = (out - run_clpost(src_dark, entry, kind, q, 0)[0], truth_lamps) if with_lamps else None
                    row = f"clpost {q}{label}"
                    rows[row] = dict(score(out, truth, entry, kind, frame, lamps), ms=ms, wall_ms=wall)
                    print(f"{name} {kind} {q}{label}: {rows[row]['psnr']:.2f} dB", flush=True)
                    if q == "final" and not label:
                        final = out
            # --merge without --blender: the earlier run's peer rows stay (clpost's are regenerated)
            kept = {k: v for k, v in earlier.get(kind, {}).items() if k not in rows and not k.startswith("clpost ")}
            results[name][kind] = {"pinhole input": rows.pop("pinhole input"), **kept, **rows}
            panels = [pinhole, truth] + ([final] if final is not None else []) + ([peer] if peer is not None else [])
            labels = ["pinhole", f"Cycles {kind}"] + (["clpost final"] if final is not None else []) + \
                     ([f"Blender {'Defocus' if kind == 'dof' else 'Vector Blur'}"] if peer is not None else [])
            sheet(panels, labels, sheets / f"sheet_{name}_{kind}.png")
            if name == "emitters" and kind == "dof" and a.figure and len(panels) == 4:
                sheet(panels, labels, Path(a.figure))
    (work / "results.json").write_text(json.dumps(results, indent=1, default=float))
    text = tables(results, manifest)
    print(text)
    if a.doc:
        doc = Path(a.doc)
        old = doc.read_text() if doc.exists() else f"{BEGIN}\n{END}\n"
        if BEGIN not in old:
            old += f"\n{BEGIN}\n{END}\n"
        args = " ".join(argv if argv is not None else sys.argv[1:])
        cmd = f"Written by `.venv/bin/python tools/cycles_compare.py {args}`" + \
            (" (scenes merged from earlier runs of the same command in --work)" if a.merge else "")
        new = re.sub(re.escape(BEGIN) + ".*?" + re.escape(END), lambda _: f"{BEGIN}\n{cmd}\n\n{text}\n{END}", old,
                     flags=re.S)
        doc.write_text(new)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
