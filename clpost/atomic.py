"""Write outputs so that a reader never sees a half-written file and an old file is never lost
to a failed write: write a temporary file in the destination directory, then ``os.replace``."""
from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Iterator


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path`` atomically, on
    error it is removed and ``path`` is untouched."""
    dest = Path(path)
    dest.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{dest.stem}.", suffix=f".tmp{dest.suffix}", dir=dest.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.replace(tmp, dest)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_png(path: str | os.PathLike, signal, encoding: str = "sRGB") -> None:
    """Display-encode a linear (H, W, 3) image (1.0 = white) and write an 8-bit PNG, atomically."""
    from PIL import Image

    from .colorspace import encode_preview

    img = encode_preview(signal, encoding, 8)
    with atomic_path(path) as tmp:
        Image.fromarray(img, mode="RGB").save(tmp, format="PNG")
