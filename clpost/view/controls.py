"""The viewer's controls, generated from the parameter declarations (:mod:`clpost.params`).

Every camera parameter that has a command-line flag gets a control: a switch for on/off, a
select for a fixed set of choices, a slider for a number (linear where the declaration's check
has both bounds, logarithmic otherwise) and, for every parameter, the value as the command line
spells it (so ``auto``, ``none``, ``thin:35``, ``36x24`` work as in ``clpost process``). A new
stage's parameters therefore get controls without touching this package. The bounds and choices
are read from the check's closure (``in_range``/``integer``/``at_least``/``one_of`` in
:mod:`clpost.params`); :data:`SLIDER_HINTS` only narrows a few open-ended ranges to what a
photographer turns (a slider from 0 to infinity has no useful middle).
"""
from __future__ import annotations

import inspect
import math
from dataclasses import dataclass
from typing import Any

from ..camera import Camera
from ..params import ParamSpec

SLIDER_HINTS: dict[str, tuple[float, float, bool]] = {
    # name: (lo, hi, logarithmic) — the ranges cameras' rings and dials cover
    "f_number": (0.7, 32.0, True),
    "focus_distance_m": (0.3, 100.0, True),
    "shutter_s": (1 / 8000, 1.0, True),
    "iso": (25.0, 25600.0, True),
    "exposure_compensation_ev": (-5.0, 5.0, False),
    "nd_stops": (0.0, 10.0, False),
    "blades": (0, 16, False),
    "blade_rotation_deg": (0.0, 360.0, False),
    "white_balance_k": (2000.0, 12000.0, True),
    "grain_amount": (0.0, 4.0, False),
    "readout_time_s": (0.0, 0.05, False),
}
"""Slider ranges for open-ended parameters (a declared bound always wins where it is tighter)."""

GROUPS = ("camera", "exposure")
"""Owners shown first (the rest follow in the stages' physical order)."""


@dataclass(frozen=True)
class Control:
    """One parameter's control. ``kind``: ``switch``, ``select``, ``slider`` or ``text``."""

    name: str
    owner: str
    flag: str
    label: str
    unit: str
    help: str
    scalar: bool
    kind: str
    choices: tuple[str, ...] = ()
    lo: float = 0.0
    hi: float = 1.0
    log: bool = False
    integer: bool = False

    def to_slider(self, value: Any) -> float | None:
        """The slider position of ``value`` (None: the value has no position, e.g. ``auto``)."""
        if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
            return None
        v = min(max(float(value), self.lo), self.hi)
        return math.log10(v) if self.log else v

    def from_slider(self, pos: float) -> float | int:
        v = 10.0 ** float(pos) if self.log else float(pos)
        if self.integer:
            return int(round(v))
        return float(f"{v:.4g}")

    @property
    def slider_range(self) -> tuple[float, float, float]:
        """(min, max, step) of the slider's position."""
        if self.log:
            return math.log10(self.lo), math.log10(self.hi), 0.005
        if self.integer:
            return self.lo, self.hi, 1
        return self.lo, self.hi, (self.hi - self.lo) / 400


def _closure(check) -> dict:
    if check is None or check.__closure__ is None:
        return {}
    return dict(inspect.getclosurevars(check).nonlocals)


def _is_number_type(spec: ParamSpec) -> tuple[bool, bool]:
    """(numeric, integer) from the declared type text and default."""
    t = str(spec.type)
    if isinstance(spec.default, (bool, tuple)) or "bool" in t or "tuple" in t:
        return False, False
    if "int" in t.split("|")[0]:
        return True, True
    return ("float" in t.split("|")[0]) or isinstance(spec.default, float), False


def control_for(spec: ParamSpec) -> Control:
    meta = spec.meta
    base = dict(name=spec.name, owner=spec.owner, flag=meta.flag, label=meta.flag.lstrip("-"), unit=meta.unit,
                help=meta.help, scalar=meta.scalar)
    if isinstance(spec.default, bool) or str(spec.type) == "bool":
        return Control(kind="switch", **base)
    env = _closure(meta.check)
    if "choices" in env:
        return Control(kind="select", choices=tuple(env["choices"]), **base)
    numeric, integer = _is_number_type(spec)
    if not numeric:
        return Control(kind="text", **base)
    lo, hi = env.get("lo"), env.get("hi")
    hint = SLIDER_HINTS.get(spec.name)
    if hint is not None:
        h_lo, h_hi, log = hint
        lo = h_lo if lo is None else max(lo, h_lo)
        hi = h_hi if hi is None or hi > 1e6 else min(hi, h_hi)
    elif lo is not None and hi is not None and hi < 1e6:
        log = False
    else:  # open-ended and no hint: a logarithmic slider over ±4 stops… 16× around the default
        d = spec.default if isinstance(spec.default, (int, float)) and spec.default else 1.0
        d = abs(float(d))
        lo, hi, log = (d / 16, d * 16, True) if lo is None or lo >= 0 else (-4 * d, 4 * d, False)
    if log and lo <= 0:
        lo = hi / 1e4
    return Control(kind="slider", lo=float(lo), hi=float(hi), log=log, integer=integer, **base)


def controls(camera_cls=Camera) -> list[Control]:
    """Every settable parameter's control, camera and exposure first, then by stage."""
    out = [control_for(s) for s in camera_cls.param_specs() if s.meta.flag is not None and not s.meta.input_only]
    order = {o: i for i, o in enumerate(GROUPS)}
    return sorted(out, key=lambda c: order.get(c.owner, len(GROUPS)))


def value_text(spec_or_control, value: Any) -> str:
    """``value`` as the command line spells it."""
    spec = {s.name: s for s in Camera.param_specs()}[spec_or_control.name]
    return spec.help_default(value)


def parse_text(name: str, text: str) -> Any:
    """The value of ``text`` as the parameter's flag reads it (InputError naming the flag)."""
    import argparse

    from ..errors import InputError

    spec = {s.name: s for s in Camera.param_specs()}[name]
    text = str(text).strip()
    if spec.meta.parse is None:
        return None if text.lower() == "none" and spec.default is None else text
    if text.lower() == "none" and spec.default is None:
        return None
    try:
        return spec.meta.parse(text)
    except (argparse.ArgumentTypeError, ValueError) as exc:
        raise InputError(f"{spec.meta.flag} {text!r}: {exc}") from None
