"""The figures of docs/raw_isp.md: a colour chart through the raw sensor and the ISP (mosaic crop,
demosaiced, camera JPEG, and the old per-pixel sensor noise beside them), and the noise power
spectrum of a demosaiced grey card against its CFA + demosaic prediction and white noise.

    .venv/bin/python tools/raw_isp_figures.py docs/figures   # needs matplotlib (the `plot` extra)
    .venv/bin/python tools/raw_isp_figures.py --time         # docs/raw_isp.md "Cost"

Numbers it prints go to docs/raw_isp.md.
"""
from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from clpost import Camera, Frame, Pipeline, raw_io, sensor_calibration as calib
from clpost.stages.isp import colour_matrix, mhc_demosaic, srgb_encode, white_balance_gains
from clpost.stages.raw import camera_matrix, cfa_channels


def chart(w=384, h=256):
    """ColorChecker 24 (colour-science's 2005 values, D65-adapted, linear sRGB) over a sweep of fine
    stripes (the demosaic's hard case)."""
    import colour

    cc = colour.CCS_COLOURCHECKERS["ColorChecker24 - After November 2014"]
    xyz = colour.xyY_to_XYZ(np.array(list(cc.data.values())))
    rgb = colour.XYZ_to_RGB(xyz, "sRGB", illuminant=cc.illuminant, chromatic_adaptation_transform="Bradford",
                            apply_cctf_encoding=False)
    img = np.zeros((h, w, 3))
    ph, pw = (h * 3 // 4) // 4, w // 6
    for k in range(24):
        r, c = divmod(k, 6)
        img[r * ph + 2:(r + 1) * ph - 2, c * pw + 2:(c + 1) * pw - 2] = np.clip(rgb[k], 0, None)
    y0 = 4 * ph
    x = np.arange(w)
    period = 2.0 + 14.0 * (1 - x / w)  # 16 → 2 px per cycle
    img[y0:] = (0.5 + 0.4 * np.cos(2 * np.pi * np.cumsum(1 / period)))[None, :, None]
    return img


def colourise(mosaic, pat):
    """Each photosite in its filter's colour (clear as white) for viewing."""
    h, w = mosaic.shape
    y, x = np.mgrid[0:h, 0:w]
    ch = cfa_channels(pat)[y % 2, x % 2]
    tint = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], float)[ch]
    return srgb_encode(np.clip(mosaic, 0, 1)[..., None] * tint)


def crops(out_dir: Path):
    import matplotlib.pyplot as plt

    img = chart()
    scale = 0.85 / img[: img.shape[0] * 3 // 4].max()  # the chart's white patch just below saturation
    sig = (img * scale).astype(np.float32)
    iso = 25600
    raw_cam = Camera(iso=iso, raw_calibration="a7s2-like")
    isp_cam = Camera(iso=iso, raw_calibration="a7s2-like", isp=True, isp_jpeg_quality=75)
    old_cam = Camera(iso=iso, sensor_preset="fullframe-cmos")
    frame = Frame(sig, metadata={"frame_index": 1})
    mosaic = Pipeline(raw_cam, stages=["raw"], already_applied=("exposure",)).run(frame).color[..., 0]
    developed = Pipeline(isp_cam, stages=["raw", "isp"], already_applied=("exposure",)).run(frame).color
    old = Pipeline(old_cam, stages=["sensor"], already_applied=("exposure",)).run(frame).color
    with tempfile.TemporaryDirectory() as tmp:
        jpg = Path(tmp) / "camera.jpg"
        raw_io.write_developed(jpg, developed, isp_cam)
        from PIL import Image

        jpeg = np.asarray(Image.open(jpg), np.float64) / 255.0
        (out_dir / "raw_isp_camera.jpg").write_bytes(jpg.read_bytes())
    # the old sensor stage has no white balance: show it through the same WB-free sRGB encoding of
    # the working space (its input is already white-balanced linear RGB)
    old_disp = srgb_encode(old)
    ys, xs = slice(20, 52), slice(96, 144)  # a crop across the patch edges (rows 1, cols 2-3)
    ys2, xs2 = slice(196, 228), slice(300, 348)  # the fine stripes
    panels = [("raw mosaic (photosites in their filter colour)", colourise(mosaic, "RGGB")),
              ("ISP: MHC demosaic + WB + matrix + sRGB", developed), ("camera JPEG, quality 75", jpeg),
              ("before: sensor stage, independent per-pixel noise", old_disp)]
    fig, axes = plt.subplots(2, 4, figsize=(14, 5.6))
    for j, (title, im) in enumerate(panels):
        for i, (yy, xx) in enumerate(((ys, xs), (ys2, xs2))):
            ax = axes[i, j]
            ax.imshow(np.clip(im[yy, xx], 0, 1), interpolation="nearest")
            ax.set_xticks([]), ax.set_yticks([])
            if i == 0:
                ax.set_title(title, fontsize=9)
    fig.suptitle(f"a7s2-like at ISO {iso}: 48×32-photosite crops (top: colour patches, bottom: fine stripes)")
    fig.tight_layout()
    fig.savefig(out_dir / "raw_isp_crops.png", dpi=80)
    plt.close(fig)


def nps_figure(out_dir: Path):
    import matplotlib.pyplot as plt

    doc = json.loads(Path(calib.load("a7s2-like").path).read_text())
    doc["iso"] = [{"iso": 800, "gain_dn_per_e": 0.8464, "read_noise_dn": 3.0, "row_noise_dn": 0.0,
                   "column_noise_dn": 0.0, "dsnu_dn": 0.0, "prnu": 0.0}]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "white.json"
        path.write_text(json.dumps(doc))
        cam = Camera(iso=800, raw_calibration=str(path), isp=True)
        c = calib.load(str(path))
        n, span = c.at_iso(800), c.white_level_dn - c.black_level_dn
        size, frames, grey = 256, 8, 0.15
        pipe = Pipeline(cam, stages=["raw", "isp"], already_applied=("exposure",))
        card = np.full((size, size, 3), grey, np.float32)
        dev = [pipe.run(Frame(card, metadata={"frame_index": k})).color.astype(np.float64) for k in range(frames)]
        y, x = np.mgrid[0:size, 0:size]
        clean = camera_matrix(cam)[cfa_channels("RGGB")[y % 2, x % 2]] @ np.full(3, grey)
        sigma = np.sqrt(n.gain_dn_per_e * clean * span + n.read_noise_dn ** 2 + 1 / 12) / span
        rng = np.random.default_rng(2020)
        wb, cm = white_balance_gains(cam), colour_matrix(cam)
        pred = [srgb_encode(np.maximum((mhc_demosaic(clean + sigma * rng.standard_normal(clean.shape), "RGGB") * wb)
                                       @ cm.T, 0)) for _ in range(frames)]

    def nps(ims):
        return np.mean([np.abs(np.fft.fft2(i - i.mean())) ** 2 / i.size for i in ims], axis=0)

    f = np.fft.fftfreq(size)
    fr = np.hypot(f[None, :], f[:, None])
    edges = np.linspace(0, 0.7072, 30)
    mids = 0.5 * (edges[1:] + edges[:-1])

    def radial(s):
        return np.array([s[(fr >= a) & (fr < b)].mean() if ((fr >= a) & (fr < b)).any() else np.nan
                         for a, b in zip(edges[:-1], edges[1:])])

    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    for k, (name, col) in enumerate(zip("RGB", ("tab:red", "tab:green", "tab:blue"))):
        a, b = nps([d[..., k] for d in dev]), nps([p[..., k] for p in pred])
        hf = lambda s: s[fr > 0.35].mean() / s[(fr > 0) & (fr < 0.15)].mean()  # noqa: E731
        print(f"{name}: HF/LF device {hf(a):.3f}, predicted {hf(b):.3f}; total power ratio {a.mean() / b.mean():.4f}")
        axes[0].semilogy(mids, radial(a), color=col, label=f"{name} device")
        axes[0].semilogy(mids, radial(b), color=col, ls="--", label=f"{name} predicted (CFA + MHC)")
        axes[0].axhline(a.mean(), color=col, ls=":", lw=1)
    axes[0].set_xlabel("radial frequency (cycles/px)"), axes[0].set_ylabel("NPS (code²·px²)")
    axes[0].set_title("radial NPS; dotted: white noise of the same variance", fontsize=9)
    axes[0].legend(fontsize=7)
    for ax, s, t in ((axes[1], nps([d[..., 1] for d in dev]), "G, device (log, DC centred)"),
                     (axes[2], nps([p[..., 1] for p in pred]), "G, predicted from white per-photosite noise")):
        ax.imshow(np.log10(np.fft.fftshift(s) + 1e-12), extent=(-0.5, 0.5, 0.5, -0.5), cmap="magma")
        ax.set_title(t, fontsize=9), ax.set_xlabel("f_x"), ax.set_ylabel("f_y")
    fig.suptitle(f"demosaiced grey card (signal {grey}, ISO 800, {frames} frames of {size}²): noise power spectrum")
    fig.tight_layout()
    fig.savefig(out_dir / "raw_isp_nps.png", dpi=64)
    plt.close(fig)


def timing():
    """Wall time per 1920×1080 frame after the first (median of 3) of raw, raw + isp and sensor."""
    import time

    c = np.random.default_rng(0).uniform(0, 0.5, (1080, 1920, 3)).astype(np.float32)
    for stages, cam in ((["sensor"], Camera(iso=1600, sensor_preset="fullframe-cmos")),
                        (["raw"], Camera(iso=1600, raw_calibration="a7s2-like")),
                        (["raw", "isp"], Camera(iso=1600, raw_calibration="a7s2-like", isp=True))):
        pipe = Pipeline(cam, stages=stages, already_applied=("exposure",))
        ts = []
        for k in range(4):
            t = time.perf_counter()
            pipe.run(Frame(c, metadata={"frame_index": k}))
            ts.append(time.perf_counter() - t)
        print(f"{'+'.join(stages)}: {np.median(ts[1:]):.3f} s/frame")


if __name__ == "__main__":
    if sys.argv[1:] == ["--time"]:
        timing()
        sys.exit(0)
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "docs/figures")
    out.mkdir(parents=True, exist_ok=True)
    crops(out)
    nps_figure(out)
