"""Frame-numbered file patterns and frame ranges.

A pattern is a path whose **file name** holds exactly one frame token (the directory part is
taken literally):

==========  ==========================================  =====================================
token       meaning                                     frame 7 / frame 1234 / frame −5
==========  ==========================================  =====================================
``#``       one digit of padding per ``#`` (Nuke,        ``####`` → ``0007`` / ``1234`` /
            oiiotool style — *not* fileseq's default    ``-005``
            "# = 4 digits")
``@``       one digit of padding per ``@``              ``@@@`` → ``007`` / ``1234`` / ``-05``
``%0Nd``    printf, zero-padded to N characters         ``%04d`` → ``0007`` / ``1234`` / ``-005``
``%d``      printf, no padding                          ``7`` / ``1234`` / ``-5``
==========  ==========================================  =====================================

Padding is a minimum width exactly as printf's ``%0Nd`` (a minus sign counts toward it); wider
frame numbers are written in full. ``%Nd`` without the 0 (space padding) is refused: spaces in
file names are never what a renderer wrote.

Frame ranges use fileseq's ``FrameSet`` syntax (the parser Nuke/OpenCue pipelines share):
``1-100``, ``1-100x2`` (step 2), ``1,3,5-7``, ``10-1`` (descending), ``1-10y3`` (the frames
``x3`` would skip). Sub-frames are refused. Order is kept as written, duplicates dropped.

Reference: fileseq documentation, https://fileseq.readthedocs.io/ (FrameSet syntax, padding
styles ``PAD_STYLE_HASH1``).
"""
from __future__ import annotations

import numbers
import os
import re
from dataclasses import dataclass
from pathlib import Path

import fileseq

from .errors import InputError

# One frame token: a run of '#', a run of '@', or a printf integer conversion.
_TOKEN = re.compile(r"#+|@+|%(?P<flags>0?)(?P<width>\d*)d")
_EXAMPLE = "e.g. 'render.####.exr', 'render.%04d.exr' or 'render.@@@@.exr'"
_RANGE_EXAMPLE = "e.g. '1-100', '1-100x2' or '1,3,5-7'"


@dataclass(frozen=True)
class FramePattern:
    """A parsed pattern: ``directory / (head + frame + tail)``; ``width`` is the minimum digits."""

    pattern: str
    directory: str
    head: str
    tail: str
    width: int

    def path(self, frame: int) -> str:
        """The path of one frame."""
        name = f"{self.head}{frame:0{self.width}d}{self.tail}"
        return os.path.join(self.directory, name) if self.directory else name


def _split(pattern: str) -> tuple[str, str]:
    if not isinstance(pattern, str) or not pattern:
        raise InputError(f"frame pattern {pattern!r} is empty or not a string; {_EXAMPLE}")
    directory, name = os.path.split(pattern)
    return directory, name


def has_pattern(pattern: str) -> bool:
    """True when the file name of ``pattern`` holds a frame token (``#``, ``@``, ``%0Nd``)."""
    _, name = _split(pattern)
    return _TOKEN.search(name) is not None


def parse_pattern(pattern: str) -> FramePattern:
    """Parse ``pattern``; InputError if its file name has no, several or a malformed token."""
    directory, name = _split(pattern)
    tokens = list(_TOKEN.finditer(name))
    if not tokens:
        raise InputError(f"frame pattern {pattern!r} has no frame token in its file name; {_EXAMPLE}")
    if len(tokens) > 1:
        found = ", ".join(repr(t.group(0)) for t in tokens)
        raise InputError(f"frame pattern {pattern!r} has {len(tokens)} frame tokens ({found}); "
                         f"use exactly one, {_EXAMPLE}")
    tok = tokens[0]
    text = tok.group(0)
    if text.startswith("%") and tok["width"] and not tok["flags"]:
        raise InputError(f"frame pattern {pattern!r}: {text!r} pads with spaces; use "
                         f"'%0{tok['width']}d' for zero padding, {_EXAMPLE}")
    # fileseq's HASH1 style is exactly our rule (one digit per '#' or '@', printf width).
    width = fileseq.getPaddingNum(text, pad_style=fileseq.PAD_STYLE_HASH1)
    return FramePattern(pattern, directory, name[:tok.start()], name[tok.end():], max(int(width), 1))


def _check_frame(frame: int) -> int:
    # numbers.Integral admits numpy integers; bool is refused because True is no frame number.
    if isinstance(frame, bool) or not isinstance(frame, numbers.Integral):
        raise InputError(f"frame number {frame!r} must be an integer; sub-frames are not supported")
    return int(frame)


def expand(pattern: str, frame: int) -> str:
    """The path of ``frame`` in ``pattern`` (``pattern`` itself if it has no frame token)."""
    frame = _check_frame(frame)
    if not has_pattern(pattern):
        return pattern
    return parse_pattern(pattern).path(frame)


def parse_frames(spec: str) -> list[int]:
    """Frames of a range spec (``1-100``, ``1-100x2``, ``1,3,5-7``) in the order written."""
    if not isinstance(spec, str) or not spec.strip():
        raise InputError(f"frame range {spec!r} is empty; {_RANGE_EXAMPLE}")
    try:
        frames = fileseq.FrameSet(spec.strip())
    except (fileseq.ParseException, fileseq.MaxSizeException, ValueError) as e:
        reason = re.sub(r":?\s*did not match\s*$", "", str(e).splitlines()[0].strip())
        raise InputError(f"frame range {spec!r} is not valid ({reason}); {_RANGE_EXAMPLE}") from None
    out = []
    for f in frames:
        if int(f) != f:
            raise InputError(f"frame range {spec!r} has sub-frame {f}; use whole frames, {_RANGE_EXAMPLE}")
        out.append(int(f))
    if not out:
        raise InputError(f"frame range {spec!r} selects no frames; {_RANGE_EXAMPLE}")
    return out


def find_frames(pattern: str) -> list[int]:
    """Frame numbers, sorted, of the files on disk that ``pattern`` names.

    A file counts only if writing its number back through the pattern gives its exact name,
    so ``img.####.exr`` finds ``img.0007.exr`` and ``img.12345.exr`` but not ``img.7.exr``.
    """
    fp = parse_pattern(pattern)
    directory = Path(fp.directory or ".")
    if not directory.is_dir():
        raise InputError(f"frame pattern {pattern!r}: directory {str(directory)!r} does not exist; check the path")
    rx = re.compile(re.escape(fp.head) + r"(-?\d+)" + re.escape(fp.tail) + r"\Z")
    frames = set()
    with os.scandir(directory) as it:
        for entry in it:
            m = rx.match(entry.name)
            if m and entry.is_file():
                n = int(m.group(1))
                if os.path.basename(fp.path(n)) == entry.name:
                    frames.add(n)
    if not frames:
        raise InputError(f"frame pattern {pattern!r} matches no files in {str(directory)!r} "
                         f"(frame 1 would be {os.path.basename(fp.path(1))!r}); check the name and padding")
    return sorted(frames)
