"""Parameters declared by the stage that reads them.

Each stage module declares its parameters as a frozen dataclass whose fields are made with
:func:`param`: default, unit, help, command-line flag and parser, validation rule, EXR header
key and whether the value is a per-frame **scalar** (a kernel argument or per-frame host value
that may change every frame without rebuilding anything: focus, f-number, shutter, exposure) or
**structural** (it changes programs, ``#define``s, tables or which stages run: lens, blades,
film stock). The stage points at it with ``params = <X>Params``.

:class:`clpost.camera.Camera` composes the camera's own parameters and every registered stage's
into one flat frozen dataclass; its validation, :meth:`~clpost.camera.Camera.describe` (the EXR
header), the CLI camera options (with their defaults in ``--help``),
:meth:`~clpost.camera.Camera.structure_key` and :meth:`~clpost.camera.Camera.scalars` are all
generated from these declarations. A params class may also define two hooks, run with the
composed camera:

- ``validate(camera, inputs)`` (staticmethod): cross-field rules of its fields; it may normalise
  values with ``object.__setattr__`` (the camera is frozen) and reads the input-only values
  (``input_only=True``: accepted by ``Camera(...)``, never stored) from ``inputs``;
- ``check_options(camera, given)`` (staticmethod): rules about which options a user *gave*
  (:meth:`clpost.camera.Camera.from_options`, used by the CLI), e.g. options that only act in
  another mode;
- ``header(camera)`` (staticmethod): extra derived EXR header entries.

Validators raise :class:`clpost.errors.InputError` with one line naming ``Camera.<field>=<value>``,
the unit and the fix.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable

from .errors import InputError

META_KEY = "clpost.param"

Check = Callable[[str, Any], Any]


@dataclass(frozen=True)
class ParamMeta:
    """What :func:`param` records on a dataclass field."""

    unit: str
    help: str
    scalar: bool
    flag: str | None = None
    parse: Callable[[str], Any] | None = None
    check: Check | None = None
    header: str | None = None
    show: Callable[[Any], str | None] | None = None
    cli_default: str | None = None
    input_only: bool = False


@dataclass(frozen=True)
class ParamSpec:
    """One composed camera parameter: its field, owner and metadata."""

    name: str
    owner: str
    """``"camera"`` for the camera core, else the stage name."""
    default: Any
    type: Any
    meta: ParamMeta
    params: type

    def header_text(self, value: Any) -> str | None:
        """The EXR header value of ``value`` (None: the key is omitted)."""
        return (self.meta.show or show_default)(value)

    def help_default(self, value: Any = dataclasses.MISSING) -> str:
        """The default (or ``value``, e.g. the demo camera's) as the command line spells it."""
        if value is dataclasses.MISSING or value == self.default:
            if self.meta.cli_default is not None:
                return self.meta.cli_default
            value = self.default
        d = value
        if d is None:
            return (self.meta.show(None) if self.meta.show is not None else None) or "none"
        if isinstance(d, bool):
            return "on" if d else "off"
        if isinstance(d, tuple):
            return "x".join(f"{v:g}" for v in d)
        if isinstance(d, float):
            return f"{d:g}"
        return str(d)


def param(default: Any, *, unit: str, help: str, scalar: bool, flag: str | None = None,
          parse: Callable[[str], Any] | None = None, check: Check | None = None, header: str | None = None,
          show: Callable[[Any], str | None] | None = None, cli_default: str | None = None,
          input_only: bool = False) -> Any:
    """A dataclass field carrying a parameter's declaration.

    ``check(name, value)`` returns the normalised value or raises InputError; ``parse(text)``
    turns command-line text into a value (default: str); ``show(value)`` the EXR header text
    (default :func:`show_default`; returning None omits the key); ``cli_default`` overrides how
    ``--help`` spells the default; ``input_only`` marks a value that ``Camera(...)`` accepts but
    does not store (a ``validate`` hook turns it into stored fields).
    """
    meta = ParamMeta(unit=unit, help=help, scalar=scalar, flag=flag, parse=parse, check=check, header=header,
                     show=show, cli_default=cli_default, input_only=input_only)
    return dataclasses.field(default=default, metadata={META_KEY: meta})


def specs_of(owner: str, cls: type) -> list[ParamSpec]:
    """The declared parameters of one params dataclass, in field order."""
    out = []
    for f in dataclasses.fields(cls):
        meta = f.metadata.get(META_KEY)
        if meta is None:
            raise TypeError(f"{cls.__name__}.{f.name} is not declared with clpost.params.param()")
        out.append(ParamSpec(f.name, owner, f.default, f.type, meta, cls))
    return out


# -- header text -------------------------------------------------------------------------------

def exact_g(value: float) -> str:
    """``%g`` when that reads back as the same float, else the shortest text that does (repr):
    headers stay readable (``0.02``, ``3``) and a camera read back from them is identical."""
    text = f"{value:g}"
    return text if float(text) == value else repr(float(value))


def show_default(value: Any) -> str | None:
    """None → omitted; numbers ``%g`` (exact: :func:`exact_g`); (w, h) → ``WxH``; anything else ``str``."""
    if value is None:
        return None
    if isinstance(value, bool) or isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return exact_g(value)
    if isinstance(value, tuple):
        return "x".join(exact_g(float(v)) for v in value)
    return str(value)


def show_auto(value: Any) -> str:
    """``auto`` for None (chosen by the meter), else ``%g`` (exact)."""
    return "auto" if value is None else exact_g(value)


def show_none(value: Any) -> str:
    """``none`` for None, else the text."""
    return "none" if value is None else str(value)


# -- command-line text -------------------------------------------------------------------------

def parse_fraction(text: str) -> float:
    """A number, a fraction like ``1/50``, or ``inf``."""
    try:
        if "/" in text:
            num, den = text.split("/", 1)
            return float(num) / float(den)
        return float(text)
    except (ValueError, ZeroDivisionError):
        raise argparse.ArgumentTypeError(f"{text!r} is not a number (e.g. 2.8, 1/50, inf)") from None


def parse_auto_or_fraction(text: str) -> float | None:
    """``auto`` (None: the meter chooses) or :func:`parse_fraction`."""
    return None if text.lower() == "auto" else parse_fraction(text)


def parse_on_off(text: str) -> bool:
    t = text.lower()
    if t in ("1", "on", "true", "yes"):
        return True
    if t in ("0", "off", "false", "no"):
        return False
    raise argparse.ArgumentTypeError(f"{text!r} is not on/off")


def parse_wxh_mm(text: str) -> tuple[float, float]:
    try:
        w, h = text.lower().split("x")
        return float(w), float(h)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not WxH in mm (e.g. 36x24)") from None


# -- validators: check(name, value) -> normalised value ----------------------------------------

def to_float(name: str, value: Any, unit: str, fix: str) -> float:
    """float(value) or InputError naming the field, unit and fix (NaN and inf pass)."""
    try:
        return float(value)
    except (TypeError, ValueError):
        raise InputError(f"Camera.{name}={value!r} is not a number ({unit}); {fix}") from None


def finite_value(name: str, value: Any, unit: str, fix: str) -> float:
    v = to_float(name, value, unit, fix)
    if not math.isfinite(v):
        raise InputError(f"Camera.{name}={value!r} must be finite ({unit}); {fix}")
    return v


def finite(unit: str, fix: str, *, optional: bool = False) -> Check:
    """A finite float (None allowed when ``optional``)."""
    def check(name, value):
        if optional and value is None:
            return None
        return finite_value(name, value, unit, fix)
    return check


def positive(unit: str, fix: str, *, optional: bool = False, message: str | None = None) -> Check:
    """A finite float > 0. ``message`` (with ``{name}``, ``{value!r}``) replaces the default text."""
    def check(name, value):
        if optional and value is None:
            return None
        v = finite_value(name, value, unit, fix)
        if v <= 0:
            raise InputError(message.format(name=name, value=value) if message else
                             f"Camera.{name}={value!r} must be > 0 {unit}, {fix}")
        return v
    return check


def in_range(lo: float, hi: float, unit: str, eg: str, *, lo_open: bool = False) -> Check:
    """A finite float in [lo, hi] (``(lo, hi]`` with ``lo_open``)."""
    def check(name, value):
        v = finite_value(name, value, unit, f"e.g. {eg}")
        if not ((lo < v if lo_open else lo <= v) and v <= hi):
            raise InputError(f"Camera.{name}={v!r} must be in {'(' if lo_open else '['}{lo:g}, {hi:g}], e.g. {eg}")
        return v
    return check


def at_least(lo: float, unit: str, fix: str, note: str) -> Check:
    """A finite float >= lo; ``note`` says what the bound means (e.g. "0 = global shutter")."""
    def check(name, value):
        v = finite_value(name, value, unit, fix)
        if v < lo:
            raise InputError(f"Camera.{name}={value!r} must be >= {lo:g} {unit} ({note})")
        return v
    return check


def one_of(*choices: str, optional: bool = False) -> Check:
    """One of the given strings (None allowed when ``optional``)."""
    def check(name, value):
        if optional and value is None:
            return None
        if value not in choices:
            quoted = [f"'{c}'" for c in choices]
            listed = quoted[0] if len(quoted) == 1 else f"{', '.join(quoted[:-1])} or {quoted[-1]}"
            raise InputError(f"Camera.{name}={value!r} must be {listed}")
        return value
    return check


def boolean(name: str, value: Any) -> bool:
    """True/False (ints 0/1 accepted)."""
    if not isinstance(value, (bool, int)):
        raise InputError(f"Camera.{name}={value!r} must be True or False")
    return bool(value)


def integer(lo: int, hi: int | None = None, *, rule: str | None = None) -> Check:
    """An integer in [lo, hi) (hi None: no upper bound); ``rule`` words the range in the message."""
    def check(name, value):
        try:
            ok = int(value) == value and int(value) >= lo and (hi is None or int(value) < hi)
        except (TypeError, ValueError, OverflowError):
            ok = False
        if not ok:
            raise InputError(f"Camera.{name}={value!r} must be {rule or f'an integer >= {lo}'}")
        return int(value)
    return check


CORNER_MM = finite("mm on the film at the image corner", "e.g. 0.1, or 0 to turn the effect off", optional=True)
"""The check of a parametric aberration coefficient (astigmatism, coma, lateral_color): None or finite mm."""
