r"""glare: diffraction starburst of the bladed aperture and veiling glare, on the highlights.

**Kernel** per channel c (wavelength :math:`\lambda_c` = 611, 549, 464 nm, the dominant
wavelengths of the Rec.709 primaries): :math:`K_c = (1-g)\,\mathrm{PSF}_{\lambda_c N_w} + g\,K_g`,
the Fraunhofer PSF of the aperture at the working f-number :math:`N_w` (f-number × bellows
factor, :func:`clpost.photometry.camera_bellows_factor`) integrated over the pixels, and the
veiling-glare kernel of fraction g = ``veiling_glare`` (formulas and sources in
:mod:`clpost.optics.diffraction`). Both sum to 1: the stage conserves energy.

**Highlights only.** With the threshold :math:`T = \texttt{glare\_threshold}/\text{gain}`
(saturations, as the ghosts stage's), each pixel splits into :math:`h = \max(v - T, 0)` and
:math:`v - h`; only h is convolved:

.. math::

    \text{out} = (v - h) + K_c * h

so a frame without pixels above T is unchanged (the stage is then not planned) and the rest of the
frame only receives the highlights' spread light.

**Convolution** by FFT on the device: h is placed in a zero-padded (H_f, W_f) grid, H_f ≥ 2H,
W_f ≥ 2W with only the factors 2, 3, 5, 7 (no wrap-around: light that leaves the frame is lost,
as it is off the sensor), transformed with VkFFT's OpenCL backend (pyvkfft; R2C, batched over the
three channels), multiplied by the kernels' spectra (computed once per camera on the host with
numpy) and transformed back. The numpy reference does the same with ``numpy.fft``.

**Without pyvkfft** (an optional extra, ``clpost[fft]``, that a plain ``pip install`` does not
build) the same convolution runs on the host (:func:`fft_backend` picks it; ``--explain`` says
which): the device splits the highlights off as above, h (3, H, W) is read back, transformed
with ``scipy.fft`` (pocketfft, float32, all cores: ``workers=-1``) on the same padded grid,
multiplied by the same spectra, transformed back, cropped to the frame, uploaded and added on
the device. Same formula, same float32 precision; the cost (two transfers of 3·H·W floats and
the host FFTs) is measured in docs/flare.md.

Quality: samples across the pupil Q (the PSF spans Q λN): draft 256, preview 512, final 1024.

The launches of pyvkfft go to the queue directly, not through the runtime's recorder, so this
stage's code runs every frame (``replay_key`` None).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..params import at_least, boolean, in_range, param, parse_fraction, parse_on_off
from . import _field as fld
from ._highlights import below_threshold, scene_threshold
from .base import GatherStage, per_camera


@dataclass(frozen=True)
class GlareParams:
    """glare: diffraction by the bladed aperture and veiling glare, applied to the highlights."""

    diffraction: bool = param(False, unit="on/off", flag="--diffraction", parse=parse_on_off, check=boolean,
                              header="clpost.diffraction", scalar=False,
                              help="diffraction starburst of the aperture on the highlights: on/off")
    veiling_glare: float = param(
        0.0, unit="fraction", flag="--veiling-glare", parse=parse_fraction, header="clpost.veilingGlare",
        check=in_range(0.0, 0.5, "fraction of the flux", "0.02 (ISO 9358 veiling glare index 2 %)"), scalar=False,
        help="share of the highlights' flux the lens scatters over the frame (0 = none)")
    veiling_glare_radius_mm: float = param(
        0.5, unit="mm", flag="--veiling-glare-radius", parse=parse_fraction, header="clpost.veilingGlareRadius_mm",
        check=in_range(0.001, 100.0, "mm on the film", "0.5"), scalar=False,
        help="core radius r0 of the veiling-glare kernel r0/(2π(r²+r0²)^1.5) in mm on the film")
    glare_threshold: float = param(
        1.0, unit="× saturation", flag="--glare-threshold", parse=parse_fraction, header="clpost.glareThreshold",
        check=at_least(0.0, "× saturation", "e.g. 1 (what clips the sensor)", "0 = every pixel"), scalar=True,
        help="only light above this many times the exposure's saturation is diffracted and scattered")


def threshold_scene(camera) -> float:
    return scene_threshold(camera, camera.glare_threshold)


def nice(n: int) -> int:
    """The smallest m ≥ n with no prime factor above 7 (sizes VkFFT and numpy transform fast)."""
    m = max(int(n), 1)
    while True:
        k = m
        for p in (2, 3, 5, 7):
            while k % p == 0:
                k //= p
        if k == 1:
            return m
        m += 1


def fft_backend() -> str:
    """"vkfft" when pyvkfft's OpenCL backend imports, else "host" (scipy.fft; module docstring)."""
    try:
        from pyvkfft.opencl import VkFFTApp  # noqa: F401
    except ImportError:
        return "host"
    return "vkfft"


def fft_shape(w: int, h: int) -> tuple[int, int]:
    return nice(2 * h), nice(2 * w)


def working_f_number(camera) -> float:
    from ..photometry import camera_bellows_factor

    return camera.f_number * camera_bellows_factor(camera)


class Glare(GatherStage):
    name = "glare"
    order = 47.0
    role = "diffraction at the aperture and scattered light, spread from the highlights (beside the ghosts, before distortion)"
    domains = ("render", "render")
    params = GlareParams
    example = dict(f_number=11.0, diffraction=True, veiling_glare=0.02, blades=6, glare_threshold=0.5)
    turn_off = "give --diffraction off and --veiling-glare 0"

    @per_camera
    def kernels(self, camera, width: int) -> np.ndarray:
        """(3, k, k) per-channel diffraction kernels on pixels (odd k, centred, each sums to 1);
        (3, 1, 1) ones without diffraction."""
        from ..optics.diffraction import PUPIL_SAMPLES, pixel_psf, unit_psf
        from .lateral_color import channel_wavelengths_nm

        if not camera.diffraction:
            return np.ones((3, 1, 1))
        q = PUPIL_SAMPLES[self.quality]
        psf = unit_psf(q, camera.blades, float(camera.blade_rotation_deg), float(camera.aperture_roundness))
        pitch_um = fld.pitch_mm(camera, width) * 1000.0
        n = working_f_number(camera)
        ks = [pixel_psf(psf, 0.5, pitch_um / (lam / 1000.0 * n)) for lam in channel_wavelengths_nm()]
        k = max(x.shape[0] for x in ks)
        out = np.zeros((3, k, k))
        for c, x in enumerate(ks):
            o = (k - x.shape[0]) // 2
            out[c, o:o + x.shape[0], o:o + x.shape[0]] = x
        return out

    @per_camera
    def spectra(self, camera, width: int, w: int, h: int) -> np.ndarray:
        """(3, H_f, W_f//2 + 1) complex128 spectra of the full kernels K_c (module docstring)."""
        from ..optics.diffraction import cauchy_kernel, embed_centred

        shape = fft_shape(w, h)
        ks = self.kernels(camera, width)
        g = camera.veiling_glare
        glare = cauchy_kernel(shape, camera.veiling_glare_radius_mm / fld.pitch_mm(camera, width)) if g > 0 else 0.0
        return np.stack([np.fft.rfft2((1.0 - g) * embed_centred(ks[c], shape) + g * glare) for c in range(3)])

    def skip_reason(self, camera, frame):
        if not camera.diffraction and camera.veiling_glare == 0:
            return "Camera.diffraction is off and Camera.veiling_glare is 0"
        return below_threshold(camera, frame, camera.glare_threshold, "highlight")

    def reason_needed(self, camera, frame):
        t = threshold_scene(camera)
        over = float(np.mean(np.max(frame.color, axis=2) > t))
        k = self.kernels(camera, fld.image_width_px(frame))
        fft = ("FFT by VkFFT on the device" if fft_backend() == "vkfft"
               else "FFT by scipy on the host (pyvkfft not installed: pip install 'clpost[fft]' for the device FFT)")
        return (f"{over * 100:.3g} % of the pixels above {camera.glare_threshold:g} × saturation; f/{working_f_number(camera):.3g} "
                f"PSF {k.shape[1]} px wide, veiling glare {camera.veiling_glare:g}; {fft}")

    def replay_key(self, camera, frame):
        return None  # pyvkfft enqueues outside the recorder, the host path reads back: run the stage's code every frame

    def enqueue(self, rt, camera, frame, src, dst, aux):
        if fft_backend() == "host":
            return self._enqueue_host(rt, camera, frame, src, dst)
        import pyopencl.array as cla
        from pyvkfft.opencl import VkFFTApp

        from ..runtime import kernel_source

        w, h = frame.width, frame.height
        hf, wf = fft_shape(w, h)
        spec = self.spectra(camera, fld.image_width_px(frame), w, h)
        key = ("glare_spec", camera, w, h, self.quality)
        kspec = rt.constant(np.ascontiguousarray(spec, np.complex64), key)
        hi = rt.scratch(self, "hi", (3, hf, wf))
        fq = rt.scratch(self, "spectrum", (3, hf, wf // 2 + 1), np.complex64)
        conv = rt.scratch(self, "conv", (3, hf, wf))
        q = rt.queue
        apps = self.__dict__.setdefault("_apps", {})
        app = apps.get((id(q), hf, wf))
        if app is None:
            apps.clear()
            app = apps[(id(q), hf, wf)] = VkFFTApp((3, hf, wf), np.float32, queue=q, ndim=2, r2c=True,
                                                   inplace=False)
        a_hi = cla.Array(q, (3, hf, wf), np.float32, data=hi)
        a_fq = cla.Array(q, (3, hf, wf // 2 + 1), np.complex64, data=fq)
        a_conv = cla.Array(q, (3, hf, wf), np.float32, data=conv)
        progs = rt.kernels(kernel_source("glare"), "glare")
        t = np.float32(threshold_scene(camera))
        events = [rt.launch(progs["glare"], (wf, hf), None, src, dst, hi, np.int32(w), np.int32(h),
                            np.int32(wf), np.int32(hf), t)]
        app.fft(a_hi, a_fq)
        n_c = 3 * hf * (wf // 2 + 1)
        events.append(rt.launch(progs["glare_multiply"], (n_c,), None, fq, kspec, np.int32(n_c)))
        app.ifft(a_fq, a_conv)
        events.append(rt.launch(progs["glare_add"], (w, h), None, dst, conv, np.int32(w), np.int32(h),
                                np.int32(wf), np.int32(hf)))
        return events

    def _enqueue_host(self, rt, camera, frame, src, dst):
        """The convolution by scipy.fft on the host (module docstring, "Without pyvkfft")."""
        import pyopencl as cl
        import scipy.fft as sfft

        from ..runtime import kernel_source

        w, h = frame.width, frame.height
        hf, wf = fft_shape(w, h)
        spec = self.spectra_f32(camera, fld.image_width_px(frame), w, h)
        hi = rt.scratch(self, "hi", (3, h, w))
        conv = rt.scratch(self, "conv", (3, h, w))
        progs = rt.kernels(kernel_source("glare"), "glare")
        t = np.float32(threshold_scene(camera))
        # the split on an unpadded grid (wf = w, hf = h): h leaves the device frame-sized
        events = [rt.launch(progs["glare"], (w, h), None, src, dst, hi, np.int32(w), np.int32(h),
                            np.int32(w), np.int32(h), t)]
        host = np.empty((3, h, w), np.float32)
        cl.enqueue_copy(rt.queue, host, hi, is_blocking=True)
        out = np.zeros((3, h, w), np.float32)
        for c in np.nonzero(host.reshape(3, -1).max(axis=1) > 0)[0]:  # a channel without highlights adds nothing
            f = sfft.rfft2(host[c], s=(hf, wf), workers=-1)
            f *= spec[c]
            out[c] = sfft.irfft2(f, s=(hf, wf), workers=-1)[:h, :w]
        self.__dict__["_upload"] = out  # alive until the non-blocking upload has read it
        events.append(rt.copy(conv, out))
        events.append(rt.launch(progs["glare_add"], (w, h), None, dst, conv, np.int32(w), np.int32(h),
                                np.int32(w), np.int32(h)))
        return events

    @per_camera
    def spectra_f32(self, camera, width: int, w: int, h: int) -> np.ndarray:
        """:meth:`spectra` as complex64 (the host path's float32 transforms)."""
        return np.ascontiguousarray(self.spectra(camera, width, w, h), np.complex64)

    def reference(self, camera, frame, color, keep_padding: bool = False):
        """float64 numpy implementation of the module docstring (``keep_padding``: also return the
        convolved highlights on the whole padded grid, for energy checks)."""
        color = np.asarray(color, np.float64)
        h, w = color.shape[:2]
        hf, wf = fft_shape(w, h)
        spec = self.spectra(camera, fld.image_width_px(frame), w, h)
        t = threshold_scene(camera)
        hi = np.maximum(color - t, 0.0)
        out = color - hi
        pads = []
        for c in range(3):
            grid = np.zeros((hf, wf))
            grid[:h, :w] = hi[..., c]
            conv = np.fft.irfft2(np.fft.rfft2(grid) * spec[c], s=(hf, wf))
            out[..., c] += conv[:h, :w]
            pads.append(conv)
        return (out, np.stack(pads)) if keep_padding else out
