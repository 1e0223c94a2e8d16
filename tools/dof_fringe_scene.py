"""A renderer-like input for dof and its exact thin-lens truth: anti-aliased colour with a
point-sampled depth, small emitters against the sky, an in-focus emitter, a blurred near pole over
a sharp mid-ground and a far wall.

    PYTHONPATH=. .venv/bin/python tools/dof_fringe_scene.py [--size 480x270] [--samples 512]
        [--out /tmp/dof16] [--qualities draft,preview,final] [--tag run]
        [--blender /work/bpyvenv/bin/python]

Why: clpost's own accumulation reference renders depth per view, so it never shows what other
renderers hand over — colour filtered over the pixel (Cycles: Blackman–Harris, 1.5 px wide) and
depth from one sample of it. Here the scene is a stack of fronto-parallel cards with analytic
shapes (discs, bars, stripes), so both the pinhole buffers and the thin-lens truth are exact
Monte Carlo integrals of the same pixel filter: a sample at image point X through aperture point
ξ (unit-radius polygon, :func:`clpost.render.thin_lens.aperture_samples`) sees card i at
X − r_i ξ, r_i its signed CoC radius (:func:`clpost.stages.dof.coc_px`), cards composited front
to back. Pinhole colour: ξ = 0 with the same filter samples; depth: the first card hit by the
first filter sample (random per pixel, like Cycles' depth pass taken from sample 0).

Prints, per quality: PSNR (sRGB view, diffuse white at 0.5 as clpost.dof_bench) and FLIP against
the truth, and per emitter its saturated area (pixels above diffuse white) and energy against the
truth's, plus the in-focus emitter's halo (pixels above 5 % of white farther than 3 px). With
``--blender``, the same rows for the peer: Blender's compositor Defocus on the same pinhole
(``tools/blender_defocus.py`` in that interpreter) and on its depth min-filtered over 3×3. The
truth is cached in ``--out`` by size and sample count.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from clpost.camera import Camera
from clpost.stages.dof import coc_px

CAMERA = dict(lens="thin:50", f_number=1.4, focus_distance_m=2.0, blades=6, depth_of_field=True)
SKY = np.array([0.55, 0.75, 1.0])
# far emitters (depth m, x, y, diameter px, brightness × white) at the reference size 480×270
EMITTERS = [(6.0, 60.3, 40.6, 1.3, 1000.0), (6.0, 110.7, 42.2, 2.2, 400.0), (9.0, 160.4, 38.5, 3.1, 200.0),
            (9.0, 215.6, 60.7, 1.6, 800.0), (12.0, 270.2, 44.4, 4.0, 100.0), (12.0, 330.5, 70.3, 2.5, 300.0)]
IN_FOCUS = [(2.0, 400.4, 50.6, 3.6, 300.0), (2.0, 440.7, 90.2, 1.4, 1000.0)]
EMITTER_RGB = np.array([1.0, 0.85, 0.6])


def _blackman_harris_offsets(rng, n, width=1.5):
    """Pixel-filter sample offsets (px), importance-sampled from Cycles' default
    Blackman–Harris filter of ``width`` px (separable here, which is close enough)."""
    t = np.linspace(0, 1, 4097)
    w = 0.35875 - 0.48829 * np.cos(2 * np.pi * t) + 0.14128 * np.cos(4 * np.pi * t) - 0.01168 * np.cos(6 * np.pi * t)
    cdf = np.concatenate([[0], np.cumsum(0.5 * (w[1:] + w[:-1]))])
    cdf /= cdf[-1]
    u = rng.random(n)
    return (np.interp(u, cdf, t) - 0.5) * width


class Scene:
    """The cards at image size (w, h); geometry given at 480×270 and scaled."""

    def __init__(self, camera: Camera, w: int, h: int, emitters: bool = True):
        self.w, self.h, s = w, h, w / 480.0
        self.s = s
        cards = []  # (depth m, kind, params); front first after sorting
        for d, x, y, dia, b in (EMITTERS + IN_FOCUS if emitters else []):
            cards.append((d, "disc", (x * s, y * s, 0.5 * dia * s, b * EMITTER_RGB)))
        cards.append((0.8, "pole", (300 * s, 316 * s)))
        cards.append((2.0, "box", (240 * s, 150 * s, 420 * s, 250 * s)))
        cards.append((1.2, "wire", (120 * s, 1.6 * s)))
        cards.append((30.0, "wall", (190 * s,)))
        cards.sort(key=lambda c: c[0])
        self.cards = cards
        self.coc = [float(coc_px(camera, d, w)) for d, _, _ in cards]

    def card(self, i, x, y):
        """(alpha, rgb) of card i at image points (x, y) (arrays)."""
        d, kind, p = self.cards[i]
        s = self.s
        if kind == "disc":
            cx, cy, r, rgb = p
            a = (x - cx) ** 2 + (y - cy) ** 2 <= r * r
            return a, np.broadcast_to(rgb, x.shape + (3,))
        if kind == "pole":
            a = (x >= p[0]) & (x < p[1])
            stripe = 0.5 + 0.5 * np.sin(y / (3.0 * s))
            rgb = np.stack([0.05 + 0.25 * stripe, 0.04 + 0.1 * stripe, 0.03 + 0.02 * stripe], -1)
            return a, rgb
        if kind == "box":
            x0, y0, x1, y1 = p
            a = (x >= x0) & (x < x1) & (y >= y0) & (y < y1)
            chk = ((np.floor(x / (6 * s)) + np.floor(y / (6 * s))) % 2)
            rgb = np.stack([0.7 - 0.5 * chk, 0.3 + 0.3 * chk, 0.2 + 0.0 * chk], -1)
            return a, rgb
        if kind == "wire":
            yc, th = p
            a = np.abs(y - yc - 0.15 * (x - self.w / 2) / s * 0.1) < 0.5 * th
            return a, np.broadcast_to(np.array([0.9, 0.9, 0.85]), x.shape + (3,))
        if kind == "wall":
            a = y >= p[0]
            chk = ((np.floor(x / (5 * s)) + np.floor(y / (4 * s))) % 2)
            rgb = np.stack([0.25 + 0.35 * chk, 0.25 + 0.3 * chk, 0.3 + 0.2 * chk], -1)
            return a, rgb
        raise ValueError(kind)

    def shade(self, x, y, lens=None):
        """Front-to-back composite at (x, y) seen through aperture point ``lens`` (unit ξ, or None
        for the pinhole); returns (rgb, depth of the first card hit)."""
        out = np.zeros(x.shape + (3,))
        trans = np.ones(x.shape)
        depth = np.full(x.shape, np.inf)
        for i, (d, _, _) in enumerate(self.cards):
            if lens is None:
                xs, ys = x, y
            else:
                xs, ys = x - self.coc[i] * lens[0], y - self.coc[i] * lens[1]
            a, rgb = self.card(i, xs, ys)
            a = a.astype(np.float64)
            hit = (trans > 0) & (a > 0)
            depth = np.where(hit & np.isinf(depth), d, depth)
            out += (trans * a)[..., None] * rgb
            trans = trans * (1 - a)
        sky = SKY * (0.8 + 0.4 * (1 - y / self.h))[..., None]
        out += trans[..., None] * sky
        return out, depth


def render(camera: Camera, w: int, h: int, samples: int, seed: int = 1, truth: bool = True,
           emitters: bool = True):
    """(pinhole colour, point-sampled depth, thin-lens truth or None)."""
    from clpost.render.thin_lens import aperture_samples

    scene = Scene(camera, w, h, emitters)
    rng = np.random.default_rng(seed)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    radius_m = camera.focal_length_mm / (2.0 * camera.f_number) * 1e-3
    lens = aperture_samples(camera, samples) / radius_m if truth else None
    pin = np.zeros((h, w, 3))
    ref = np.zeros((h, w, 3)) if truth else None
    depth = None
    for j in range(samples):
        ox = _blackman_harris_offsets(rng, w * h).reshape(h, w)
        oy = _blackman_harris_offsets(rng, w * h).reshape(h, w)
        c, d = scene.shade(xs + ox, ys + oy)
        pin += c
        if depth is None:
            depth = d
        if truth:
            ref += scene.shade(xs + ox, ys + oy, lens[j])[0]
    return pin / samples, depth, (ref / samples if truth else None)


def emitter_stats(img, base, scene_w, kind="far"):
    """Per emitter: (saturated area px, energy) of img − base in a window around it."""
    s = scene_w / 480.0
    rows = []
    for d, x, y, dia, b in (EMITTERS if kind == "far" else IN_FOCUS):
        r = int(math.ceil(14 * s))
        cx, cy = int(round(x * s)), int(round(y * s))
        win = (slice(cy - r, cy + r + 1), slice(cx - r, cx + r + 1))
        diff = img[win] - base[win]
        lum = diff @ np.array([0.2126, 0.7152, 0.0722])
        sat = int(np.count_nonzero(img[win] @ np.array([0.2126, 0.7152, 0.0722]) > 1.0))
        yy, xx = np.mgrid[win]
        far = np.hypot(xx - x * s, yy - y * s) > 3 * s + 0.5 * dia * s
        halo = int(np.count_nonzero((lum > 0.05) & far))
        rows.append((d, dia, b, sat, float(lum.sum()), halo))
    return rows


def _blender(python, camera, frame, out, min_z):
    """Blender's Defocus node on ``frame`` (tools/blender_defocus.py in the bpy interpreter)."""
    import subprocess

    from clpost.exr import read_frame, write_frame
    from clpost.frame import Frame

    depth = frame.depth
    if min_z:
        p = np.pad(depth, 1, mode="edge")
        depth = np.min([p[1 + dy:1 + dy + depth.shape[0], 1 + dx:1 + dx + depth.shape[1]]
                        for dy in (-1, 0, 1) for dx in (-1, 0, 1)], axis=0)
    src, dst = out / f"blender_in_{int(min_z)}.exr", out / f"blender_out_{int(min_z)}.exr"
    write_frame(src, Frame(color=frame.color, depth=depth))
    tool = Path(__file__).with_name("blender_defocus.py")
    subprocess.run([python, str(tool), str(src), str(dst), "--f-number", str(camera.f_number),
                    "--focal-mm", str(camera.focal_length_mm), "--sensor-mm", str(camera.sensor_mm[0]),
                    "--focus-m", str(camera.focus_distance_m), "--blades", str(camera.blades),
                    "--max-blur", "64", "--threads", "1", "--repeats", "1"],
                   check=True, stdout=subprocess.DEVNULL)
    return read_frame(dst).color


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", default="480x270")
    ap.add_argument("--samples", type=int, default=512)
    ap.add_argument("--out", default="/tmp/dof16")
    ap.add_argument("--qualities", default="draft,preview,final")
    ap.add_argument("--tag", default="run")
    ap.add_argument("--blender", help="a Python with bpy: also score Blender's Defocus node")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.split("x"))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    camera = Camera(**CAMERA)
    cache = out / f"fringe_{w}x{h}_{args.samples}.npz"
    if cache.exists():
        z = np.load(cache)
        pin, depth, ref, base = z["pin"], z["depth"], z["ref"], z["base"]
    else:
        pin, depth, ref = render(camera, w, h, args.samples)
        # the truth without emitters: the background each emitter's energy is measured against
        base = render(camera, w, h, args.samples, emitters=False)[2]
        np.savez_compressed(cache, pin=pin, depth=depth, ref=ref, base=base)
    from clpost.atomic import write_png
    from clpost.dof_bench import VIEW_SCALE, flip_ldr, srgb
    from clpost.frame import Frame
    from clpost.pipeline import Pipeline

    def psnr_srgb(a, b):
        x = np.clip(srgb(np.clip(a * VIEW_SCALE, 0, None)), 0, 1)
        y = np.clip(srgb(np.clip(b * VIEW_SCALE, 0, None)), 0, 1)
        return 10 * math.log10(1.0 / float(np.mean((x - y) ** 2)))

    write_png(str(out / "fringe_truth.png"), ref * VIEW_SCALE)
    write_png(str(out / "fringe_pinhole.png"), pin * VIEW_SCALE)
    truth_far = emitter_stats(ref, base, w)
    truth_in = emitter_stats(ref, base, w, "in")
    print(f"pinhole: PSNR {psnr_srgb(ref, pin):.2f} dB  FLIP {flip_ldr(ref, pin):.4f}")
    frame = Frame(color=pin.astype(np.float32), depth=depth.astype(np.float32))
    results = [(q, lambda q=q: Pipeline(camera, quality=q, stages=["dof"]).run(frame).color)
               for q in args.qualities.split(",")]
    if args.blender:
        results += [("blender", lambda: _blender(args.blender, camera, frame, out, False)),
                    ("blender-minZ", lambda: _blender(args.blender, camera, frame, out, True))]
    for q, make in results:
        res = np.asarray(make(), np.float64)
        write_png(str(out / f"fringe_{args.tag}_{q}.png"), res * VIEW_SCALE)
        np.save(out / f"fringe_{args.tag}_{q}.npy", res)
        print(f"{q}: PSNR {psnr_srgb(ref, res):.2f} dB  FLIP {flip_ldr(ref, res):.4f}")
        for t, c in zip(truth_far, emitter_stats(res, base, w)):
            print(f"   emitter {t[0]:4.0f} m {t[1]:.1f} px ×{t[2]:<5.0f} sat area {c[3]:4d} / {t[3]:4d} "
                  f"({c[3] / max(t[3], 1):.2f}×)  energy {c[4] / t[4]:.3f}×")
        for t, c in zip(truth_in, emitter_stats(res, base, w, "in")):
            print(f"   in-focus emitter {t[1]:.1f} px: halo px {c[5]} (truth {t[5]}), energy {c[4] / t[4]:.3f}×")
    return 0


if __name__ == "__main__":
    sys.exit(main())
