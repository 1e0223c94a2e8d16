"""``clpost view``'s web page: a trame (Kitware) app over :class:`~clpost.view.session.ViewSession`.

trame serves its own Vue and Vuetify bundles and fonts from the Python packages, so the page works
offline. The page talks to this process over one websocket: controls set state here, and the
frame, histogram and status come back as state (images as data URLs).

Progressive rendering: every change renders a ``draft`` frame at once (a newer change while one
is rendering is coalesced: the latest wins); when nothing changed for :data:`IDLE_S`, the frame is
rendered again at the chosen quality. Rendering runs on one worker thread (the OpenCL queue and the
plans live there), never on the event loop.
"""
from __future__ import annotations

import asyncio
import concurrent.futures
import math
import time
from typing import Any

from ..errors import InputError
from .controls import Control, controls, parse_text, value_text
from .session import (DRAFT, ViewSession, ab_split, data_url, false_colour, histogram, lens_datasheet,
                      zebras)

IDLE_S = 0.35
"""Seconds without a change before the chosen quality is rendered."""

ZOOMS = ("fit", "1:1", "2:1", "4:1")


def _key(c: Control) -> str:
    return f"p_{c.name}"


def _slider_key(c: Control) -> str:
    return f"s_{c.name}"


class ViewApp:
    """The trame server, its layout and the render loop."""

    def __init__(self, session: ViewSession, server=None) -> None:
        from trame.app import get_server

        self.session = session
        self.server = server or get_server(name=None, client_type="vue3")
        self.controls = controls()
        self._by_key = {_key(c): c for c in self.controls}
        self._executor = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="clpost-view")
        self._wake: asyncio.Event | None = None
        self._generation = 0
        self._last_change: str | None = None
        self._lens_shown: tuple | None = None
        self._good = None  # the last camera that rendered
        self._init_state()
        self._bind()
        self._layout()

    # -- state ---------------------------------------------------------------------------------
    def _init_state(self) -> None:
        st, s = self.server.state, self.session
        for c in self.controls:
            v = getattr(s.camera, c.name)
            st[_key(c)] = v if c.kind == "switch" else value_text(c, v)
            if c.kind == "slider":
                st[_slider_key(c)] = c.to_slider(v)
        st.update(dict(
            image="", histogram="", datasheet="", status="starting…", timings=[], plan_text="", error="",
            frame_index=0, n_frames=len(s.frame_numbers), frame_label=str(s.frame_numbers[0]),
            track_text=s.track_json(0),
            split=1.0, zoom="fit", overlay="none", quality=s.final_quality, command=s.command(),
            track_path="camera-track.json", saved="", rendered_quality="", focus_mark="",
            renders=0, width=s.frame(0).windows.display_size[0], height=s.frame(0).windows.display_size[1],
        ))

    def _bind(self) -> None:
        st, ctrl = self.server.state, self.server.controller
        for c in self.controls:
            st.change(_key(c))(self._text_handler(c))
            if c.kind == "slider":
                st.change(_slider_key(c))(self._slider_handler(c))
        st.change("frame_index", "split", "overlay")(lambda **_: self.request("view"))
        st.change("quality")(self._quality_changed)
        ctrl.add_key = self.add_key
        ctrl.save_track = self.save_track
        ctrl.on_server_ready.add(self._start_loop)

    def _quality_changed(self, quality, **_) -> None:
        self.session.final_quality = quality
        self.server.state.command = self.session.command()
        self.request("quality")

    def _text_handler(self, c: Control):
        def handler(**kw):
            raw = kw[_key(c)]
            try:
                value = raw if c.kind == "switch" else parse_text(c.name, raw)
                if value == getattr(self.session.camera, c.name):
                    return
                self.apply({c.name: value}, c.name)
            except InputError as exc:
                self.server.state.error = str(exc)
                return
            if c.kind == "slider":
                pos = c.to_slider(value)
                if pos is not None:
                    self.server.state[_slider_key(c)] = pos
        return handler

    def _slider_handler(self, c: Control):
        def handler(**kw):
            pos = kw[_slider_key(c)]
            if pos is None:
                return
            value = c.from_slider(pos)
            current = getattr(self.session.camera, c.name)
            if isinstance(current, (int, float)) and c.to_slider(current) is not None \
                    and abs(c.to_slider(current) - float(pos)) < 1e-9:
                return  # the slider followed the text
            try:
                self.apply({c.name: value}, c.name)
            except InputError as exc:
                self.server.state.error = str(exc)
                return
            self.server.state[_key(c)] = value_text(c, value)
        return handler

    def _sync_controls(self) -> None:
        """Every control's state from the session's camera (after it was put back)."""
        st = self.server.state
        for c in self.controls:
            v = getattr(self.session.camera, c.name)
            st[_key(c)] = v if c.kind == "switch" else value_text(c, v)
            if c.kind == "slider" and c.to_slider(v) is not None:
                st[_slider_key(c)] = c.to_slider(v)
        st.command = self.session.command()

    def apply(self, values: dict[str, Any], changed: str) -> None:
        """Set camera values (InputError leaves the camera as it was) and render."""
        cam = self.session.with_values(values)
        self.session.set_camera(cam)
        st = self.server.state
        st.error = ""
        st.command = self.session.command()
        st.track_text = self.session.track_json(st.frame_index)
        self._last_change = changed
        self.request(changed)

    # -- interactions ----------------------------------------------------------------------------
    def tap(self, x: float, y: float, shown_w: float, shown_h: float) -> None:
        """A click on the image at (x, y) of the shown (w, h) px: focus at that pixel's depth."""
        st = self.server.state
        px = float(x) / max(float(shown_w), 1.0) * st.width
        py = float(y) / max(float(shown_h), 1.0) * st.height
        try:
            depth = self.session.focus_at(st.frame_index, px, py)
        except InputError as exc:
            st.error = str(exc)
            return
        c = next(c for c in self.controls if c.name == "focus_distance_m")
        st.focus_mark = f"focus {depth:g} m at pixel ({px:.0f}, {py:.0f})"
        st[_key(c)] = value_text(c, depth)  # the text handler applies it (and moves the slider)

    def add_key(self) -> None:
        st = self.server.state
        self.session.add_key(st.frame_index)
        st.track_text = self.session.track_json(st.frame_index)

    def save_track(self) -> None:
        st = self.server.state
        try:
            p = self.session.save_track(st.track_path, st.frame_index)
            st.saved, st.error = f"saved {p}", ""
        except InputError as exc:
            st.error = str(exc)
        st.track_text = self.session.track_json(st.frame_index)

    # -- the render loop ---------------------------------------------------------------------------
    def request(self, why: str) -> None:
        self._generation += 1
        if self._wake is not None:
            self._wake.set()

    def _start_loop(self, **_) -> None:
        self._wake = asyncio.Event()
        self._wake.set()
        asyncio.get_event_loop().create_task(self._loop())

    async def _loop(self) -> None:
        loop = asyncio.get_event_loop()
        while True:
            await self._wake.wait()
            self._wake.clear()
            gen = self._generation
            await self._show(loop, DRAFT)
            if self._generation != gen:
                continue  # changed while rendering: draft the newest first
            try:
                await asyncio.wait_for(self._wake.wait(), IDLE_S)
                continue  # still moving
            except asyncio.TimeoutError:
                pass
            quality = self.server.state.quality
            if quality != DRAFT and self._generation == gen:
                await self._show(loop, quality)
            if self._generation == gen:
                await self._show_datasheet(loop)

    async def _show_datasheet(self, loop) -> None:
        """The traced lens's datasheet, when idle and when lens, sensor or focus changed (matplotlib: ~1 s)."""
        cam = self.session.camera
        key = (cam.lens, cam.sensor_mm, round(cam.focus_distance_m, 3))
        if key == self._lens_shown:
            return
        self._lens_shown = key
        try:
            url = await loop.run_in_executor(self._executor, lens_datasheet, cam)
        except Exception as exc:  # noqa: BLE001 - the frame matters more than its datasheet
            url, msg = None, f"lens datasheet: {type(exc).__name__}: {exc}"
            with self.server.state as st:
                st.error = " ".join(msg.split())
        with self.server.state as st:
            st.datasheet = url or ""

    async def _show(self, loop, quality: str) -> None:
        st = self.server.state
        args = (st.frame_index, quality, st.split, st.overlay)
        camera = self.session.camera
        try:
            page = await loop.run_in_executor(self._executor, self._render_page, *args)
        except Exception as exc:  # noqa: BLE001 - one line on the page; the loop and the server go on
            msg = str(exc) if isinstance(exc, InputError) else f"{type(exc).__name__}: {exc}"
            if self._good is not None and self.session.camera is camera:
                self.session.set_camera(self._good)  # back to the last camera that rendered
                msg += " (the last working settings are kept)"
            with st:
                st.error = " ".join(msg.split())
                self._sync_controls()
            return
        self._good = camera
        with st:
            st.update(page)

    def _render_page(self, index: int, quality: str, split: float, overlay: str) -> dict:
        """Worker thread: the frame and everything drawn from it, as state values."""
        s = self.session
        t0 = time.perf_counter()
        r = s.render(index, quality)
        img = r.display
        if overlay == "false colour":
            img = false_colour(r.linear, r.camera.working_space)
        elif overlay == "zebras":
            img = zebras(img)
        if split < 1.0:
            img = ab_split(img, s.pinhole(index, r.camera), split)
        page = {"image": data_url(img), "histogram": data_url(histogram(r.display), "PNG"),
                "rendered_quality": quality, "frame_label": str(s.frame_numbers[index])}
        total = (time.perf_counter() - t0) * 1e3
        change = self._last_change
        scalar = next((c.scalar for c in self.controls if c.name == change), None)
        if r.built:
            how = f"plan built in {r.build_ms:.0f} ms" + (f" ({change}: structural)" if change else "")
        else:
            how = "plan reused" + (f" ({change}: per-frame scalar, no rebuild)" if scalar else "")
        page["plan_text"] = " → ".join(r.stages) or "(no stage runs)"
        page["timings"] = [{"name": k, "ms": round(v, 1)} for k, v in r.timings.items()]
        page["status"] = (f"{quality}: {total:.0f} ms to the page (process {r.total_ms:.0f} ms) · {how} · "
                          f"f/{r.camera.f_number:.3g} {_shutter(r.camera.shutter_s)} ISO {r.camera.iso:g} "
                          f"focus {r.camera.focus_distance_m:g} m")
        page["renders"] = self.server.state.renders + 1
        return page

    def close(self) -> None:
        self._executor.shutdown(wait=True, cancel_futures=True)

    # -- layout ------------------------------------------------------------------------------------
    def _layout(self) -> None:
        from trame.ui.vuetify3 import SinglePageWithDrawerLayout
        from trame.widgets import html
        from trame.widgets import vuetify3 as v

        with SinglePageWithDrawerLayout(self.server, full_height=True) as layout:
            layout.title.set_text("clpost view")
            self.server.state.trame__title = "clpost view"
            layout.drawer.width = 380
            with layout.toolbar:
                v.VSpacer()
                html.Div("{{ status }}", id="status", style="font-size: 12px; margin-right: 12px")
            with layout.drawer:
                self._controls_panel(v, html)
            with layout.content:
                with v.VContainer(fluid=True, classes="pa-2"):
                    self._toolbar(v, html)
                    with html.Div(style="overflow: auto; max-height: 70vh; border: 1px solid #444",
                                  id="viewport"):
                        html.Img(
                            id="frame", src=("image",),
                            style=("zoom === 'fit' ? 'width: 100%; display: block; cursor: crosshair' : "
                                   "`width: ${width * parseInt(zoom)}px; image-rendering: pixelated; "
                                   "display: block; cursor: crosshair`",),
                            click=(self.tap, "[$event.offsetX, $event.offsetY, $event.target.clientWidth, "
                                             "$event.target.clientHeight]"),
                        )
                    html.Div("{{ error }}", id="error", style="color: #f66; min-height: 1.2em")
                    html.Div("{{ renders }}", id="renders", style="display: none")  # frames shown (tests wait on it)
                    with v.VRow(classes="mt-2"):
                        with v.VCol(cols=4):
                            html.Div("histogram (display code values)", classes="text-caption")
                            html.Img(id="histogram", src=("histogram",), style="width: 256px; height: 100px")
                            html.Div("plan: {{ plan_text }}", id="plan", classes="text-caption mt-2")
                            with html.Table(classes="text-caption", id="timings"):
                                with html.Tr(v_for="t in timings", key="t.name"):
                                    html.Td("{{ t.name }}", style="padding-right: 12px")
                                    html.Td("{{ t.ms }} ms", style="text-align: right")
                        with v.VCol(cols=8):
                            html.Div("lens datasheet (traced lenses; drawn when idle)", classes="text-caption")
                            html.Img(src=("datasheet",), v_show="datasheet", style="max-width: 100%")
                    with v.VRow():
                        with v.VCol(cols=12):
                            v.VTextField(v_model=("command",), label="as a clpost process command",
                                         readonly=True, density="compact", id="command")
                            v.VBtn("copy as command", size="small",
                                   click="utils.get('navigator.clipboard') && "
                                         "utils.get('navigator.clipboard').writeText(command).catch(() => 0)",
                                   classes="mr-2", id="copy")
                            v.VBtn("add key at this frame", click=self.add_key, size="small", classes="mr-2")
                            with html.Div(id="track-path", style="width: 360px; display: inline-block; vertical-align: middle",
                                          classes="mr-2"):
                                v.VTextField(v_model=("track_path",), label="camera track file (.json)",
                                             density="compact", hide_details=True)
                            v.VBtn("save camera track", click=self.save_track, size="small", id="save-track",
                                   classes="mr-2")
                            v.VBtn("download", size="small", id="download-track",
                                   click="utils.download(track_path, track_text, 'application/json')")
                            html.Span("{{ saved }}", classes="text-caption ml-2")
                            html.Pre("{{ track_text }}", classes="text-caption")

    def _toolbar(self, v, html) -> None:
        with v.VRow(dense=True, align="center"):
            with v.VCol(cols=3):
                v.VSlider(v_model_number=("frame_index",), min=0, max=("n_frames - 1",), step=1,
                          label="frame", hide_details=True, density="compact",
                          disabled=("n_frames < 2",), id="frame-slider")
                html.Span("{{ frame_label }}", classes="text-caption")
            with v.VCol(cols=3):
                v.VSlider(v_model_number=("split",), min=0, max=1, step=0.01, hide_details=True,
                          density="compact", label="A | B pinhole", id="split")
            with v.VCol(cols=2):
                v.VSelect(v_model=("zoom",), items=("zooms", list(ZOOMS)), label="zoom", density="compact",
                          hide_details=True)
            with v.VCol(cols=2):
                v.VSelect(v_model=("overlay",), items=("overlays", ["none", "false colour", "zebras"]),
                          label="exposure tool", density="compact", hide_details=True, id="overlay")
            with v.VCol(cols=2):
                v.VSelect(v_model=("quality",), items=("qualities", ["draft", "preview", "final"]),
                          label="quality when idle", density="compact", hide_details=True)
        html.Div("{{ focus_mark }} · showing {{ rendered_quality }}", classes="text-caption", id="focus-mark")

    def _controls_panel(self, v, html) -> None:
        groups: dict[str, list[Control]] = {}
        for c in self.controls:
            groups.setdefault(c.owner, []).append(c)
        with v.VExpansionPanels(multiple=True, model_value=("open_groups", [0, 1, 2]), variant="accordion"):
            for owner, cs in groups.items():
                with v.VExpansionPanel(title=owner):
                    with v.VExpansionPanelText():
                        for c in cs:
                            self._control(v, html, c)

    def _control(self, v, html, c: Control) -> None:
        tag = "" if c.scalar else " ⟳"
        tip = f"{c.help} [{c.unit}]" + ("" if c.scalar else " — structural: changes the plan (rebuild)")
        with html.Div(classes="mb-1", title=tip, id=f"ctl-{c.label}"):
            if c.kind == "switch":
                v.VSwitch(v_model=(_key(c),), label=f"{c.label}{tag}", density="compact", hide_details=True,
                          color="primary")
                return
            if c.kind == "select":
                v.VSelect(v_model=(_key(c),), items=(f"choices_{c.name}", list(c.choices)),
                          label=f"{c.label}{tag}", density="compact", hide_details=True)
                return
            with v.VRow(dense=True, align="center", no_gutters=True):
                if c.kind == "slider":
                    lo, hi, step = c.slider_range
                    with v.VCol(cols=7), html.Div(id=f"slider-{c.label}"):
                        v.VSlider(v_model_number=(_slider_key(c),), min=lo, max=hi, step=step,
                                  label=f"{c.label}{tag}", hide_details=True, density="compact")
                with v.VCol(cols=5 if c.kind == "slider" else 12), html.Div(id=f"text-{c.label}"):
                    # set on Enter or leaving the field (a half-typed "thin:3" must not build a plan)
                    v.VTextField(model_value=(_key(c),), density="compact", hide_details=True,
                                 label=None if c.kind == "slider" else f"{c.label}{tag}",
                                 change=f"set('{_key(c)}', $event.target.value)")


def _shutter(t: float) -> str:
    if t is None or not math.isfinite(t):
        return "?"
    return f"1/{1 / t:.0f} s" if t < 0.5 else f"{t:.2g} s"
