"""A camera's chain of stages: resolve the camera per frame, decide what runs, run it.

:class:`Pipeline` decides which stages change the image for this camera and frame (a stage that
is an identity is not planned — "model only what the scene requires"; :meth:`Pipeline.explain`
says why for each) and hands the frame to a :class:`~clpost.plan.Plan` — built once per camera
structure, frame size and planned stages, then reused: per-frame scalars (auto-exposure, an
animated focus) are kernel arguments, so they never rebuild anything. Kernel code generation and
device layouts: :mod:`clpost.codegen`; plan time vs call time: :mod:`clpost.plan`.
"""
from __future__ import annotations

import warnings

import numpy as np

from .camera import Camera
from .errors import InputError
from .frame import Frame, Windows
from . import metering
from .plan import Buffers, Plan, PlanEntry, group_nodes, resized_view, structure_key
from .stages import QUALITIES, Stage, registry

__all__ = ["Buffers", "Pipeline", "Plan", "PlanEntry", "resized_view"]


def _check_calibration_focal(cam: Camera) -> None:
    """Warn when a calibration's focal length disagrees with the camera's lens and sensor: the
    distortion stage uses the calibration, while vignetting, dof and the aberrations use the
    camera's f / pixel pitch."""
    model = cam.distortion
    if model is None:
        return
    f_cam = cam.intrinsics(model.width, model.height)[0]
    if abs(model.fx - f_cam) > 0.01 * f_cam:
        warnings.warn(f"calibration{model._where()} has f_x = {model.fx:.6g} px but the camera "
                      f"({cam.lens}, {cam.sensor_mm[0]:g} mm wide) gives {f_cam:.6g} px at "
                      f"{model.width} px: vignetting, dof and aberrations follow the camera; set "
                      "--lens/--sensor to match the calibration", stacklevel=3)


def check_prerequisites(stages: list[Stage], entries: list[PlanEntry], selected: set[str] | None,
                        already_applied: frozenset[str], cam: Camera, frame: Frame) -> None:
    """Refuse a plan in which a stage runs without a stage it ``requires``: one the selection
    (``--stages``) leaves out although it would change this frame (it is not an identity) and
    that the input does not already carry (``already_applied``). Its output is the planned
    stage's input domain (grain on film densities, not on scene light), so the result would be
    nonsense, not an approximation."""
    if selected is None:
        return  # every stage is a candidate: a needed prerequisite is planned
    by_name = {st.name: st for st in stages}

    def missing(name):  # the needed prerequisites of ``name`` left out, nearest first
        return [r for r in by_name[name].requires if r not in selected and r not in already_applied
                and by_name[r].skip_reason(cam, frame) is None]  # else an identity here

    for name in (e.stage for e in entries if e.planned):
        first = missing(name)
        if not first:
            continue
        add, todo = set(), list(first)
        while todo:  # and what those need in turn, so the fix is complete
            r = todo.pop()
            if r not in add:
                add.add(r)
                todo.extend(missing(r))
        fixed = [st.name for st in stages if st.name in selected or st.name in add]
        raise InputError(f"--stages: stage '{name}' works on the output of the '{first[0]}' stage, which is "
                         f"not selected; add the missing stage(s): --stages {','.join(fixed)}")


class Pipeline:
    """A camera's chain of stages, planned per frame and run with OpenCL.

    ``stages`` restricts the candidates to the named stages (compositors often want one effect);
    ``device`` is a substring of an OpenCL platform/device name (see :mod:`clpost.runtime`).
    ``already_applied`` names stages whose effect the input already carries (e.g. film densities
    from an earlier run): the stages that ``require`` them may then run without them.
    """

    def __init__(self, camera: Camera, quality: str = "final", stages: list[str] | None = None,
                 device: str | None = None, already_applied: tuple[str, ...] = ()) -> None:
        if not isinstance(camera, Camera):
            raise InputError(f"Pipeline: camera must be a clpost.Camera, not {type(camera).__name__}")
        if quality not in QUALITIES:
            raise InputError(f"quality {quality!r} is unknown: use one of {', '.join(QUALITIES)}")
        known = registry()
        if stages is not None:
            unknown = [s for s in stages if s not in known]
            if unknown:
                raise InputError(f"--stages: unknown stage(s) {', '.join(unknown)}; known: {', '.join(known)}")
        self.camera = camera
        self.quality = quality
        self.device = device
        self._selected = None if stages is None else set(stages)
        unknown = [s for s in already_applied if s not in known]
        if unknown:
            raise InputError(f"already_applied: unknown stage(s) {', '.join(unknown)}; known: {', '.join(known)}")
        self._already_applied = frozenset(already_applied)
        self._stages = [cls(quality) for cls in known.values()]
        self._runtime = None
        self._plans: dict[tuple, Plan] = {}
        self._buffers: Buffers | None = None
        self.last_plan: Plan | None = None
        self._exposure_checked = False


    # -- planning -----------------------------------------------------------------------------
    @property
    def runtime(self):
        if self._runtime is None:
            from .runtime import get_runtime

            self._runtime = get_runtime(self.device)
        return self._runtime

    def camera_for(self, frame: Frame, camera: Camera | None = None) -> Camera:
        """The camera resolved for this frame: auto-exposure metered, and a lens_data lens without
        a calibration given its traced distortion at the frame's size. ``camera``: this frame's
        camera before that (an animated camera, :mod:`clpost.camera_sources`; default the
        pipeline's)."""
        base = self.camera if camera is None else camera
        cam = metering.resolve(base, frame)
        if base.distortion is not None:
            _check_calibration_focal(cam)
        if cam.distortion is None and cam.optics is not None and cam.lens_distortion:
            from .calibration import lens_distortion_model

            # the lens distorts the image (the display window), not the overscan around it
            model = lens_distortion_model(cam, frame.windows.display_size)
            if model is not None:
                cam = cam.with_(distortion=model)
        return cam

    def explain(self, frame: Frame, camera: Camera | None = None, reasons: bool = True) -> list[PlanEntry]:
        """Every known stage, in physical order, with whether it runs and why (``reasons=False``:
        a planned stage's reason is left empty — some cost a pass over the frame on the host,
        e.g. dof's CoC range, and running a frame does not need them)."""
        cam = camera or self.camera_for(frame)
        out = []
        for st in self._stages:
            if self._selected is not None and st.name not in self._selected:
                out.append(PlanEntry(st.name, False, "not selected by --stages"))
                continue
            why = st.skip_reason(cam, frame)
            if why is None:
                missing = [b for b in st.reads if getattr(frame, b) is None]
                if missing:
                    src = frame.metadata.get("path")
                    raise InputError(
                        (f"{src}: " if src else "") +
                        f"stage '{st.name}' needs the frame's {' and '.join(missing)} buffer; "
                        f"re-render with that pass, or {st.turn_off}"
                    )
                out.append(PlanEntry(st.name, True, st.reason_needed(cam, frame) if reasons else ""))
            else:
                out.append(PlanEntry(st.name, False, why))
        check_prerequisites(self._stages, out, self._selected, self._already_applied, cam, frame)
        if frame.front is not None and not any(e.planned for e in out if e.stage == "front_layer"):
            src = frame.metadata.get("path")
            raise InputError((f"{src}: " if src else "") + "the frame has a front layer (Frame.front, --front) but "
                             "--stages leaves out front_layer, which would drop it; add front_layer to --stages")
        return out

    def plan(self, frame: Frame) -> list[str]:
        """Names of the stages that run for this frame, in order."""
        return [e.stage for e in self.explain(frame) if e.planned]

    def _planned(self, frame: Frame, cam: Camera) -> list[Stage]:
        names = {e.stage for e in self.explain(frame, cam, reasons=False) if e.planned}
        return [s.planned_form(cam, frame) for s in self._stages if s.name in names]

    def plan_for(self, frame: Frame, camera: Camera | None = None) -> Plan:
        """The :class:`~clpost.plan.Plan` for this frame: built on first use, then reused for
        every frame with the same camera structure, size and planned stages (per-frame scalars —
        auto-exposure, an animated focus — do not make a new one). ``camera``: the resolved camera
        (default :meth:`camera_for`)."""
        if not isinstance(frame, Frame):
            raise InputError(f"Pipeline.run takes a clpost.Frame, not {type(frame).__name__}; wrap "
                             "arrays with clpost.Frame(color=...) (depth=, velocity= as the stages need)")
        cam = camera or self.camera_for(frame)
        planned = self._planned(frame, cam)
        key = (structure_key(cam), frame.size,
               tuple((s.name, tuple(sorted(s.defines(cam).items()))) for s in planned))
        plan = self._plans.get(key)
        if plan is None or plan.closed:
            if len(self._plans) >= self.MAX_PLANS:  # a long run over many sizes: drop the oldest
                self._plans.pop(next(iter(self._plans)))
            bufs = self._buffers if self._buffers is not None and self._buffers.size == frame.size else None
            plan = Plan(self.runtime, cam, frame, planned, self.quality, bufs)
            self._plans[key] = plan
        self._buffers = plan.buffers
        return plan

    MAX_PLANS = 16
    """Plans kept per pipeline (each holds kernels and, per size, device buffers)."""

    def close(self) -> None:
        """:meth:`Plan.close` every plan this pipeline made (waits for their submitted frames
        in flight and stops the download thread) and forget them: a later :meth:`run` or
        :meth:`plan_for` plans anew. Idempotent; ``with Pipeline(...) as pipe:`` closes at the
        end of the block."""
        for plan in self._plans.values():
            plan.close()
        self._plans.clear()
        self._buffers = None
        self.last_plan = None

    def __enter__(self) -> "Pipeline":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def kernels(self, frame: Frame) -> list[str]:
        """The kernel launches of this frame's plan (fused groups joined by ``__``)."""
        cam = self.camera_for(frame)
        return [n.name for n in group_nodes(self._planned(frame, cam))]

    # -- running ------------------------------------------------------------------------------
    def run(self, frame: Frame, camera: Camera | None = None, out: np.ndarray | None = None) -> Frame:
        """Process one frame; returns a new Frame whose color is the camera's output
        (normalised sensor signal; later stages: the film/sensor's recorded values).
        ``camera``: this frame's camera (an animated camera; default the pipeline's): its scalar
        parameters change per frame through the same plan; its metadata ``resolved_camera`` is
        the camera used (metered). ``out``: an array to download the image into
        (:meth:`Plan.run`'s, e.g. an earlier output that is done with: a sequence then allocates
        no fresh frame), used when it fits this frame's plan, else a new one."""
        if camera is not None and not isinstance(camera, Camera):
            raise InputError(f"Pipeline.run: camera must be a clpost.Camera, not {type(camera).__name__}")
        frame = self.plate(frame, camera)
        cam = self.camera_for(frame, camera) if isinstance(frame, Frame) else None
        plan = self.plan_for(frame, cam)
        if cam is not None and not self._exposure_checked and (self._selected is None or "exposure" in self._selected):
            # once per pipeline (a sequence): a manual exposure far from mid-grey is one warning line
            self._exposure_checked = True
            metering.check_exposure(cam, frame)
        self.last_plan = plan
        w, h = plan.output_size
        fits = (out is not None and out.shape == (h, w, 3) and out.dtype == np.float32
                and out.flags.c_contiguous and out.flags.writeable)
        out = plan.run(frame, cam, out if fits else None)
        meta = dict(out.metadata, resolved_camera=cam)
        if "distortion" in plan.stage_names:
            # the distorted image is the calibration's: data = display = the output, at (0, 0)
            meta["windows"] = Windows.full(out.width, out.height)
        return out.replace(metadata=meta, validate=False)

    def plate(self, frame, camera=None):
        """A plate rendered at the infinity-focus field of view (``Camera.plate_fov``) magnified to
        the focused camera's — this frame's ``camera`` (a focus pull breathes), default the
        pipeline's — first (:func:`clpost.breathing.rescale_plate`); other frames as they are.
        The step before :meth:`camera_for`, for callers that run plans themselves (``expose``)."""
        cam = camera or self.camera
        if not isinstance(frame, Frame) or cam.plate_fov == "focused":
            return frame
        from .breathing import rescale_plate

        return rescale_plate(frame, cam)

    @property
    def last_timings(self) -> dict[str, float]:
        """Device milliseconds of the last :meth:`run`, per kernel and for upload/download."""
        return self.last_plan.last_timings if self.last_plan is not None else {}

    def reference(self, frame: Frame) -> np.ndarray:
        """The same plan through each stage's float64 numpy reference; returns (H, W, 3) float64."""
        frame = self.plate(frame)
        cam = self.camera_for(frame)
        return Plan(None, cam, frame, self._planned(frame, cam), self.quality, build=False).reference(frame, cam)
