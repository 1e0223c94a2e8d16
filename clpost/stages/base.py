"""What a stage is.

A stage is one physical effect. Its module (``clpost/stages/<name>.py``) holds one subclass of
:class:`Stage` with:

- ``name`` — used alike in ``--stages``, ``kernels/<name>.cl`` and ``tests/test_<name>.py``;
- ``order`` — its place in the physical order of light through the camera, ``role`` — why it sits
  there (one line; ``clpost stages`` lists them), and ``domains`` — what its input and output are
  (:data:`DOMAINS`); :func:`clpost.stages.order_problems` checks the order against the domains;
- ``reads`` — the Frame buffers it needs besides color (``"depth"``, ``"velocity"``);
- ``requires`` — the stages whose output it takes as its input (grain and print work on the film
  stage's densities; film and sensor on the exposure stage's normalised signal): the planner
  refuses a plan that leaves one out while it would change the image;
- ``params`` — the frozen dataclass declaring the camera parameters it owns (fields made with
  :func:`clpost.params.param`: unit, flag, help, default, check, header key, scalar or
  structural); :class:`clpost.camera.Camera`, its validation and ``describe()`` and the CLI
  options are generated from it. None: the stage reads only the camera core's parameters;
- ``skip_reason(camera, frame)`` — why it is an identity for this camera and frame, or None;
- ``reference(camera, frame, color)`` — a readable float64 numpy implementation (the oracle);
- its OpenCL implementation: a :class:`PointwiseStage` supplies a width-generic per-pixel function
  ``void <name>_apply(CLP_F *r, CLP_F *g, CLP_F *b, const CLP_CTX p, <args>)`` in
  ``kernels/<name>.cl`` that the planner fuses with its pointwise neighbours into one kernel, run
  as two 16-lane vectors per work-item (:mod:`clpost.codegen`, "Width-generic code"); a :class:`GatherStage`
  enqueues its own kernels on planar buffers through the runtime's toolkit
  (:meth:`~clpost.runtime.Runtime.kernel`, ``constant``, ``scratch``, ``cached``, ``launch``).

Structural parameters (tap counts, LUT sizes) are ``defines`` — part of the program key;
name them ``<STAGE>_...`` so fused groups never clash. Per-frame scalars are kernel arguments,
so changing exposure never recompiles anything.

How the planner calls a stage (:mod:`clpost.pipeline`):

- pointwise: ``<name>_apply(&r, &g, &b, p, [depth], [velocity], <args...>)`` where ``p`` is the
  pixel context (``CLP_X(p)``, ``CLP_INDEX(p)``, ...) and ``depth``/``velocity`` are passed only if
  the stage lists them in ``reads`` (``CLP_PLANE(depth, p)``; ``CLP_PLANE2(velocity, p, 0|1)``).
- gather: ``enqueue(rt, camera, frame, src, dst, aux)`` with planar float32 ``src``/``dst``
  (channel c of pixel i at ``c*W*H + i``), ``aux["depth"]`` / ``aux["velocity"]`` device
  buffers for what it ``reads``; it gets its kernels from ``rt.kernel`` (cached), its tables from
  ``rt.constant`` and its work buffers from ``rt.scratch(self, name, shape)``, and launches with
  ``rt.launch`` (plan-time work: ``rt.launch_once``; transfers: ``rt.copy``). Returns the events
  it enqueued (profiled). The plan records these launches and replays them on later frames
  without running ``enqueue`` (:mod:`clpost.runtime_record`) while the camera and
  :meth:`GatherStage.replay_key` stay the same: enqueue through ``rt`` only, and read nothing
  back from the device.
- ``reference()`` gets float64 color and the host Frame; tests compare the two on odd sizes,
  after asserting that the stage is planned (``tests/conftest.py``: ``assert_planned``; an
  unplanned stage is the identity on both sides).
"""
from __future__ import annotations

import functools
from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, ClassVar

import numpy as np


if TYPE_CHECKING:
    from ..camera import Camera
    from ..frame import Frame
    from ..runtime import Runtime

DOMAINS = {
    "render": "scene-linear light in the undistorted (pinhole) render's geometry",
    "image": "scene-linear light in the distorted image's (sensor's) geometry",
    "signal": "normalised sensor signal (1.0 = saturation), linear",
    "density": "developed film dye densities (Status M) per layer",
    "raw": "a digital sensor's recorded values",
    "print": "a paper print or re-linearised image, display-referred",
}
"""What a stage's input and output are (``Stage.domains``). A stage whose input and output domain
are the same transforms within it; one that changes the domain converts. Physical order follows:
every converter into a stage's input domain runs before it, and every transform within a domain
runs before the converter out of it (:func:`clpost.stages.order_problems`)."""

QUALITIES = ("draft", "preview", "final")
"""Quality levels; each stage documents what they change (sample counts, resolution)."""


class DeviceTable:
    """A pointwise stage's table argument that the device builds from small host inputs, which
    :meth:`PointwiseStage.values` returns in place of a host array when the table is big and
    changes with a per-frame scalar (vignetting's W×H plane, interpolated from a LUT that a focus
    pull changes every frame): the plan enqueues ``fill(rt, buffer, upload) -> [(label, event)]``
    into the argument's buffer — on the compute queue, in order — only when ``key`` (what
    determines the content) changes, so a frame's host work is the small inputs, not a pass over
    the pixels. ``fill`` copies its host inputs with ``upload(buffer, host) -> event`` (the plan's:
    not blocking; :meth:`clpost.plan.Plan.submit` stages them per frame in flight)."""

    def __init__(self, key, shape: tuple[int, ...], fill, dtype=np.float32) -> None:
        self.key = key
        self.shape = tuple(int(v) for v in shape)
        self.dtype = np.dtype(dtype)
        self.fill = fill

    @property
    def nbytes(self) -> int:
        return int(np.prod(self.shape)) * self.dtype.itemsize


def per_camera(method):
    """Memoise a stage method ``method(self, camera, *args)`` per camera value and arguments (the
    last 8, on the stage): LUTs sampled from a camera's curves are plan-time work, not per-frame
    work, yet a camera may change between frames (an iris ramp changes a vignetting LUT) — keying on the whole
    (frozen, hashable) camera keeps both right. Arrays come back read-only."""
    slot = "_per_camera_" + method.__name__

    @functools.wraps(method)
    def wrapper(self, camera, *args):
        memo = self.__dict__.setdefault(slot, {})
        key = (camera, *args)
        try:
            return memo[key]
        except KeyError:
            pass
        value = method(self, camera, *args)
        if isinstance(value, np.ndarray):
            value.setflags(write=False)
        if len(memo) >= 8:
            memo.pop(next(iter(memo)))
        memo[key] = value
        return value

    return wrapper


class Stage(ABC):
    name: ClassVar[str]
    order: ClassVar[float]
    role: ClassVar[str] = ""
    domains: ClassVar[tuple[str, str]] = ("render", "render")
    reads: ClassVar[tuple[str, ...]] = ()
    example: ClassVar[dict] = {}
    """Camera fields for which the stage is planned (generic tests run every stage with it: the
    16-pixel check of the fused kernels, ``tests/test_pipeline.py``)."""
    turn_off: ClassVar[str] = "leave the stage out with --stages"
    """How a user turns the stage off (said when a buffer it ``reads`` is missing)."""
    requires: ClassVar[tuple[str, ...]] = ()
    """Stages this one presupposes (their output is its input domain), by name."""
    kind: ClassVar[str] = "stage"
    params: ClassVar[type | None] = None

    def __init__(self, quality: str = "final") -> None:
        self.quality = quality

    @abstractmethod
    def skip_reason(self, camera: "Camera", frame: "Frame") -> str | None:
        """Why this stage leaves the image unchanged for this camera/frame (None: it is needed)."""

    def reason_needed(self, camera: "Camera", frame: "Frame") -> str:
        """One line saying what the stage does to this frame (for ``--explain``)."""
        return "changes the image"

    @abstractmethod
    def reference(self, camera: "Camera", frame: "Frame", color: np.ndarray) -> np.ndarray:
        """float64 numpy oracle: ``color`` (H, W, 3) float64 in, same shape out."""

    def defines(self, camera: "Camera") -> dict[str, object]:
        """Structural ``#define``s (part of the program key); none by default."""
        return {}

    def planned_form(self, camera: "Camera", frame: "Frame") -> "Stage":
        """The object the plan runs for this stage with this camera and frame: itself, or — where a
        gather stage's work is per pixel for this camera (white grain) — a :class:`PointwiseStage`
        of the same name, which the planner fuses with its pointwise neighbours. The choice may
        depend only on what a plan is keyed by (the camera's structure, the frame's size, the
        quality)."""
        return self

    def replay_key(self, camera: "Camera", frame: "Frame") -> object:
        """What this stage's launches depend on besides the camera (a plan compares the camera
        itself). A plan records a gather stage's launches (:meth:`GatherStage.enqueue`,
        :meth:`GatherStage.enqueue_host_buffers`) once and replays them while the camera and this
        key stay the same (:mod:`clpost.runtime_record`); a pointwise stage's :meth:`values` are
        computed again only when they change. Default: the frame's size, its data and display
        windows (overscan moves the principal point in the arrays), its recorded intrinsics and
        which buffers it has. A stage whose launches or values read more of the frame (its
        index for noise, a statistic of its pixels) adds it; None: run the stage's code every
        frame. Launch sizes and arguments must never depend on pixel data read back from the
        device."""
        from ._field import frame_intrinsics

        return (frame.size, frame.windows, frame_intrinsics(frame), frame.depth is None, frame.velocity is None,
                frame.alpha is None)


class PointwiseStage(Stage):
    """A per-pixel function, fused with neighbouring pointwise stages into one kernel.

    ``args`` lists the extra kernel arguments of ``<name>_apply`` as ``(OpenCL type, name)``;
    :meth:`values` gives their per-frame values in that order (numpy scalars or host arrays,
    which the planner uploads into device buffers).
    """

    kind = "pointwise"
    args: ClassVar[tuple[tuple[str, str], ...]] = ()
    state: ClassVar[bool] = False
    """Whether the stage shares work between the pixels of a work-item: its source then defines,
    per width, a type ``CLP_FN(<name>_state)`` and ``void CLP_FN(<name>_prepare)(const CLP_CTX p,
    CLP_FN(<name>_state) *st, <args>)``: the generated kernel calls ``prepare`` once per 32-pixel
    block of a row (x0 a multiple of 32, ``p`` its first 16-lane vector) to fill ``st[0]`` and
    ``st[1]`` for the vectors at x0 and x0 + 16, and passes each vector's slot to ``<name>_apply``
    right after ``p`` (:data:`clpost.codegen.ITEM_VECTORS`; white grain: one float16 of Box–Muller
    draws is the normals of the block's 32 pixels). The one-pixel form prepares ``st[0]`` per
    pixel."""

    def source(self) -> str:
        """Width-generic OpenCL C defining ``<name>_apply`` (default: ``kernels/<name>.cl``)."""
        from ..runtime import kernel_source

        return kernel_source(self.name)

    @abstractmethod
    def values(self, camera: "Camera", frame: "Frame") -> tuple:
        """Per-frame kernel argument values, in the order of ``args``."""


class GatherStage(Stage):
    """A neighbourhood operation with its own kernels on planar float32 color buffers."""

    kind = "gather"

    @abstractmethod
    def enqueue(self, rt: "Runtime", camera: "Camera", frame: "Frame", src, dst, aux: dict) -> list:
        """Enqueue the stage reading planar ``src`` and writing planar ``dst``; return events."""

    def output_size(self, camera: "Camera", frame: "Frame") -> tuple[int, int]:
        """(width, height) of ``dst``; the planner runs every later node at this size. Default:
        the frame's size (only a resampling stage such as distortion changes it)."""
        return frame.size

    def enqueue_host_buffers(self, rt: "Runtime", camera: "Camera", frame: "Frame", aux: dict) -> tuple[dict, list]:
        """:meth:`host_buffers` for :meth:`clpost.plan.Plan.run`: a stage may compute them on the
        device and download them without blocking into the arrays it returns (the plan's final
        download waits for them); returns (buffers, [(timing label, event), …]) — the label is the
        stage's name for its kernels, ``upload``/``download`` for copies. Default:
        :meth:`host_buffers`."""
        return self.host_buffers(camera, frame), []

    def host_buffers(self, camera: "Camera", frame: "Frame") -> dict:
        """Host buffers of the output Frame this stage replaces (``alpha``, ``depth``,
        ``velocity``), e.g. alpha 0 where a resampling had no data. Default: none."""
        return {}
