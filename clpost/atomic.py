"""Write outputs so that a reader never sees a half-written file and an old file is never lost
to a failed write: write a temporary file in the destination directory, then ``os.replace``.

This module owns every temporary file clpost writes. Each is named ``.<name>.tmp-<8 random characters><suffix>``
beside its destination ``<name>`` and registered while it exists:

- an exception or Ctrl-C removes it (``atomic_path``);
- SIGTERM removes the registered ones, then raises :class:`Terminated` in the main thread so the
  run unwinds (locks released) — :func:`signal_cleanup`;
- SIGKILL cannot be caught: the next run on the same outputs removes the stale ones of that
  naming pattern (:func:`remove_stale_temps`, called under the output lock), never other files.

No ``fsync``: like OpenImageIO's and Nuke's writers, a file is written and renamed without forcing
it to the disk first. The guarantee above holds without it — however a run is interrupted, an
output's name only ever points at a complete file, because the rename is the last step and is
atomic — and a sequence does not wait on the disk per frame. What it leaves to the operating
system is durability across a power loss or kernel crash: a file renamed just before one may come
back short on a filesystem that reorders the rename before the data (ext4 flushes a file that
replaces another by rename, ``auto_da_alloc``, but a new name is not covered). Rerun such a run
with ``--overwrite``: resuming skips outputs that exist.
"""
from __future__ import annotations

import contextlib
import os
import re
import signal
import tempfile
import threading
from pathlib import Path
from typing import Iterator

from .errors import OutputError

_LIVE: set[str] = set()
"""Temporary files being written by this process."""
_LIVE_LOCK = threading.Lock()
# tempfile.mkstemp's random part: 8 characters of [a-z0-9_].
_RANDOM = r"[a-z0-9_]{8}"


class Terminated(BaseException):
    """SIGTERM arrived: unwinds like Ctrl-C (not an ``Exception``, so nothing swallows it)."""


def temp_prefix(dest: Path) -> str:
    return f".{dest.name}.tmp-"


def is_temp_of(name: str, dest: Path) -> bool:
    """Whether file ``name`` is one of our temporary files for ``dest`` (same directory)."""
    rx = re.escape(temp_prefix(dest)) + _RANDOM + re.escape(dest.suffix) + r"\Z"
    return re.match(rx, name) is not None


def remove_stale_temps(dests) -> list[Path]:
    """Remove leftover temporary files of ``dests`` (a crashed or SIGKILLed earlier run) that this
    process is not writing; only names of our pattern for exactly those outputs. Returns them."""
    by_dir: dict[Path, list[Path]] = {}
    for d in dests:
        d = Path(d)
        by_dir.setdefault(d.parent, []).append(d)
    removed = []
    for directory, ds in by_dir.items():
        prefixes = {temp_prefix(d): d for d in ds}
        try:
            names = os.listdir(directory)
        except OSError:
            continue
        for name in names:
            if not name.startswith(".") or ".tmp-" not in name:
                continue
            dest = prefixes.get(name[:name.index(".tmp-") + 5])
            path = directory / name
            if dest is None or not is_temp_of(name, dest):
                continue
            with _LIVE_LOCK:
                live = str(path) in _LIVE
            if not live and path.is_file() and not path.is_symlink():
                with contextlib.suppress(FileNotFoundError):
                    path.unlink()
                    removed.append(path)
    return removed


def _cleanup_live() -> None:
    with _LIVE_LOCK:
        paths = list(_LIVE)
    for tmp in paths:
        with contextlib.suppress(OSError):
            os.unlink(tmp)


def _on_sigterm(signum, frame):  # pragma: no cover - exercised by the soak test in a subprocess
    _cleanup_live()
    raise Terminated(f"signal {signum}")


@contextlib.contextmanager
def signal_cleanup() -> Iterator[None]:
    """Meanwhile, SIGTERM (and SIGHUP) remove this process's temporary files and raise
    :class:`Terminated`; the previous handlers come back afterwards. Main thread only (elsewhere
    a no-op); SIGINT already raises KeyboardInterrupt, which ``atomic_path`` handles."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    sigs = [s for s in (signal.SIGTERM, getattr(signal, "SIGHUP", None)) if s is not None]
    previous = {s: signal.signal(s, _on_sigterm) for s in sigs}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path`` atomically, on
    error it is removed and ``path`` is untouched."""
    dest = Path(path)
    try:
        dest.parent.mkdir(parents=True, exist_ok=True)
        # mkstemp: O_EXCL (never someone else's file), in the destination's directory so that
        # os.replace is a same-filesystem rename.
        fd, tmp = tempfile.mkstemp(prefix=f".{dest.name}.tmp-", suffix=dest.suffix, dir=dest.parent)
    except OSError as e:
        raise OutputError(f"{dest}: cannot create a file in {dest.parent} ({e.strerror}); "
                          "check the directory is writable") from None
    with _LIVE_LOCK:
        _LIVE.add(tmp)
    os.close(fd)
    try:
        os.chmod(tmp, 0o666 & ~_umask())
        yield Path(tmp)
        try:
            os.replace(tmp, dest)
        except OSError as e:
            raise OutputError(f"{dest}: cannot replace it ({e.strerror}); the path must be a writable "
                              "file, not a directory") from None
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    finally:
        with _LIVE_LOCK:
            _LIVE.discard(tmp)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_png(path: str | os.PathLike, signal, *, display: str = "srgb",
              working_space: str = "rec709") -> None:
    """Display-encode a linear (H, W, 3) image (1.0 = white) and write an 8-bit PNG, atomically,
    with the display's ICC profile: :func:`clpost.display_image.write_image` (whatever the name's
    extension, the file is a PNG)."""
    from .display_image import write_image

    write_image(path, signal, display=display, working_space=working_space, fmt="PNG")
