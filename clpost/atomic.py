"""Write outputs so that a reader never sees a half-written file and an old file is never lost
to a failed write: write a temporary file in the destination directory, then ``os.replace``."""
from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Iterator

from .errors import OutputError


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
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_umask())
    try:
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


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_png(path: str | os.PathLike, signal, *, display: str = "srgb",
              working_space: str = "rec709") -> None:
    """Display-encode a linear (H, W, 3) image (1.0 = white) and write an 8-bit PNG, atomically:
    ``working_space`` primaries → the ``display``'s (``colorspace.DISPLAYS``: srgb, rec709,
    display-p3), clipped, encoded, quantised."""
    from PIL import Image

    from .colorspace import display_encode

    img = display_encode(signal, working_space, display, 8)
    with atomic_path(path) as tmp:
        Image.fromarray(img, mode="RGB").save(tmp, format="PNG")
