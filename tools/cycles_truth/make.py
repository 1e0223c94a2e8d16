"""Render and store the whole Cycles ground-truth suite (tests/data/cycles/).

    /work/bpyvenv/bin/python tools/cycles_truth/make.py [--scenes emitters,thin] [--spp 512] \\
        [--pinhole-spp 256] [--threads 2] [--raw /tmp/cycles/raw] [--out tests/data/cycles]

Per scene (each render in its own Blender process, tools/cycles_truth/render.py):

- ``pinhole.exr``: the artist's export, byte for byte as Blender wrote it (multilayer, float,
  ZIP; Combined, Depth, Vector, and Emit for the metrics), seed 0.
- ``fg.exr`` and ``bg.exr`` (``--layers``; the scenes of ``scenes.FOREGROUND``): the same
  export split into two layers — the foreground objects over a transparent film and the rest
  without them (``render.py``'s ``fg`` and ``bg`` kinds), as Blender wrote them, seed 0: the
  input of the ``front_layer`` stage (tools/cycles_truth/two_layers.py).
- ``dof.exr`` (every scene), ``motion.exr`` and ``dofmotion.exr`` (scenes with motion): the mean
  of two Cycles renders with seeds 1 and 2, stored as half-float RGB (ZIP), with the Emit pass (the
  lamps alone) as emit.R/G/B. The two seeds'
  PSNR (sRGB view, :func:`clpost.fidelity.psnr_srgb`) is the scene's **noise floor**; the stored
  mean is √2 less noisy than one seed (6 dB better against the true image than the floor).

``manifest.json`` records the command, Blender version, samples, seeds, render times, the noise
floors and each scene's camera and lamps (pixel position, depth, size), which is all that
tools/cycles_compare.py and the tests need — neither needs Blender.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import time

import numpy as np
import OpenEXR

HERE = os.path.dirname(os.path.abspath(__file__))
CAM_Z = 1.5  # scenes.CAM_Z (not imported: scenes.py needs bpy)


def read_pass(path, name="Combined"):
    """RGB of one pass of a Blender multilayer EXR (float64)."""
    f = OpenEXR.File(path, separate_channels=True)
    for part in f.parts:
        ch = part.channels
        names = [n for n in ch if n.endswith(f".{name}.R")]
        if names:
            pre = names[0][:-1]
            return np.stack([ch[pre + c].pixels for c in "RGB"], -1).astype(np.float64)
    raise SystemExit(f"{path}: no {name} pass")


def srgb_view(x):
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def psnr_srgb(a, b):
    mse = float(np.mean((srgb_view(a) - srgb_view(b)) ** 2))
    return float("inf") if mse == 0 else 10 * math.log10(1.0 / mse)


def write_truth(path, rgb, emit):
    """Half-float R, G, B (the image) and emit.R/G/B (the lamps alone), ZIP, atomically."""
    chans = {c: np.ascontiguousarray(rgb[..., i], dtype=np.float16) for i, c in enumerate("RGB")}
    chans.update({f"emit.{c}": np.ascontiguousarray(emit[..., i], dtype=np.float16) for i, c in enumerate("RGB")})
    tmp = path + ".tmp.exr"
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, chans).write(tmp)
    os.replace(tmp, path)


def render(scene, kind, path, spp, seed, threads, threshold, reuse=False, size="480x270"):
    if reuse and os.path.exists(path + ".json"):
        with open(path + ".json") as fh:
            info = json.load(fh)
        if (info["spp"], info["seed"], info["adaptive_threshold"], "x".join(map(str, info["size"]))) == \
                (spp, seed, threshold, size):
            return info
    cmd = [sys.executable, os.path.join(HERE, "render.py"), scene, kind, path, "--spp", str(spp),
           "--seed", str(seed), "--threads", str(threads), "--threshold", str(threshold), "--size", size]
    print(" ".join(cmd), flush=True)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    with open(path + ".json") as fh:
        return json.load(fh)


def lamps_px(shot, w, h):
    """Each lamp's pixel centre (OpenCV convention: pixel (i, j) centred at (i, j)), depth and size."""
    f_px = shot["focal_mm"] * w / shot["sensor_mm"]
    out = []
    for name, (x, y, z), radius in shot["lamps"]:
        out.append({"name": name, "x_px": (w - 1) / 2 + f_px * x / y, "y_px": (h - 1) / 2 - f_px * (z - CAM_Z) / y,
                    "depth_m": y, "diameter_px": 2 * radius * f_px / y})
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", default="emitters,highlights,thin,occluder,transparent,macro,motion")
    p.add_argument("--spp", type=int, default=512, help="samples of each truth render")
    p.add_argument("--pinhole-spp", type=int, default=256)
    p.add_argument("--threshold", type=float, default=0.0, help="adaptive sampling threshold (0: off)")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--size", default="480x270", help="WxH (the held-out scenes: 320x180)")
    p.add_argument("--raw", default="/tmp/cycles/raw")
    p.add_argument("--reuse", action="store_true", help="keep raw renders already in --raw with the same settings")
    p.add_argument("--out", default=os.path.join(HERE, "..", "..", "tests", "data", "cycles"))
    p.add_argument("--layers", action="store_true", help="also render the fg and bg layers (scenes.FOREGROUND)")
    p.add_argument("--layers-only", action="store_true",
                   help="render only the layers, into the scene's entry already in the manifest")
    a = p.parse_args(argv)
    os.makedirs(a.raw, exist_ok=True)
    out = os.path.abspath(a.out)
    os.makedirs(out, exist_ok=True)
    man_path = os.path.join(out, "manifest.json")
    manifest = json.load(open(man_path)) if os.path.exists(man_path) else {"scenes": {}}
    for scene in a.scenes.split(","):
        t0 = time.time()
        d = os.path.join(out, scene)
        os.makedirs(d, exist_ok=True)
        if a.layers_only:
            if scene not in manifest["scenes"]:
                raise SystemExit(f"make.py: --layers-only needs {scene} in {man_path}; render it first")
            entry = manifest["scenes"][scene]
            entry["layers"] = render_layers(scene, d, a)
            write_manifest(man_path, scene, entry)
            continue
        pin_raw = os.path.join(a.raw, f"{scene}_pinhole.exr")
        info = render(scene, "pinhole", pin_raw, a.pinhole_spp, 0, a.threads, a.threshold, a.reuse, a.size)
        shutil.copyfile(pin_raw, os.path.join(d, "pinhole.exr"))
        shot = info["shot"]
        w, h = info["size"]
        entry = {"size": [w, h], "blender": info["blender"], "shot": shot, "lamps": lamps_px(shot, w, h),
                 "pinhole": {"file": f"{scene}/pinhole.exr", "spp": a.pinhole_spp, "seed": 0,
                             "render_s": info["render_s"]}, "truths": {}}
        kinds = ["dof"] + (["motion", "dofmotion"] if shot["motion"] else [])
        for kind in kinds:
            imgs, emits, times = [], [], []
            for seed in (1, 2):
                raw = os.path.join(a.raw, f"{scene}_{kind}_s{seed}.exr")
                info_k = render(scene, kind, raw, a.spp, seed, a.threads, a.threshold, a.reuse, a.size)
                times.append(info_k["render_s"])
                imgs.append(read_pass(raw))
                emits.append(read_pass(raw, "Emission"))
            floor = psnr_srgb(imgs[0], imgs[1])
            write_truth(os.path.join(d, f"{kind}.exr"), (imgs[0] + imgs[1]) / 2, (emits[0] + emits[1]) / 2)
            entry["truths"][kind] = {"file": f"{scene}/{kind}.exr", "spp": a.spp, "seeds": [1, 2],
                                     "adaptive_threshold": a.threshold, "render_s": times,
                                     "noise_floor_psnr_srgb_db": round(floor, 2)}
            print(f"{scene} {kind}: floor {floor:.2f} dB, {times} s", flush=True)
        if a.layers:
            entry["layers"] = render_layers(scene, d, a)
        entry["wall_s"] = round(time.time() - t0, 1)
        rel_out = os.path.relpath(out, os.path.join(HERE, "..", ".."))
        entry["command"] = (f"/work/bpyvenv/bin/python tools/cycles_truth/make.py --scenes {scene} --spp {a.spp} "
                            f"--pinhole-spp {a.pinhole_spp} --threshold {a.threshold:g}"
                            + ("" if a.size == "480x270" else f" --size {a.size}")
                            + ("" if rel_out == os.path.join("tests", "data", "cycles") else f" --out {rel_out}"))
        write_manifest(man_path, scene, entry)
    return 0


def render_layers(scene, d, a) -> dict:
    """fg.exr and bg.exr of ``scene`` into folder ``d`` (as Blender wrote them); their manifest entry."""
    out = {}
    for kind in ("fg", "bg"):
        raw = os.path.join(a.raw, f"{scene}_{kind}.exr")
        info = render(scene, kind, raw, a.pinhole_spp, 0, a.threads, a.threshold, a.reuse, a.size)
        shutil.copyfile(raw, os.path.join(d, f"{kind}.exr"))
        out[kind] = {"file": f"{scene}/{kind}.exr", "spp": a.pinhole_spp, "seed": 0, "render_s": info["render_s"]}
    rel_out = os.path.relpath(os.path.dirname(d), os.path.join(HERE, "..", ".."))
    out["command"] = (f"/work/bpyvenv/bin/python tools/cycles_truth/make.py --scenes {scene} --layers-only "
                      f"--pinhole-spp {a.pinhole_spp} --out {rel_out}")
    return out


def write_manifest(man_path, scene, entry) -> None:
    manifest = json.load(open(man_path)) if os.path.exists(man_path) else {"scenes": {}}
    manifest["scenes"][scene] = entry  # re-read first: another make.py may have added scenes meanwhile
    manifest.pop("command", None)  # per scene now
    manifest["note"] = "written by tools/cycles_truth/make.py; see tests/data/cycles/README.md"
    tmp = man_path + ".tmp"
    with open(tmp, "w") as fh:
        json.dump(manifest, fh, indent=1)
    os.replace(tmp, man_path)


if __name__ == "__main__":
    raise SystemExit(main())
