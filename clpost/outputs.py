"""Where a run reads and writes: the one place that checks input and output paths and owns the
output lock.

- :func:`check_paths` refuses, before anything is written, an output that *is* an input (same
  file after resolving symlinks and relative paths, or the same inode), an input that is a
  directory or missing, and an output that is a directory.
- :class:`OutputLock` is a lock file beside the output (``.<pattern name>.lock``, JSON with pid,
  host, start time) held for the whole run, so two runs into one output sequence cannot mix
  their frames: a second run is refused with one line naming the first; the lock of a process
  that no longer exists (SIGKILL, power loss) is taken over. Under the lock, stale temporary
  files of the target outputs (:func:`clpost.atomic.remove_stale_temps`) are removed, and each
  frame's "exists, skip" check happens while the lock is held.
"""
from __future__ import annotations

import contextlib
import json
import os
import socket
import time
from pathlib import Path
from typing import Iterable, Sequence

from .atomic import remove_stale_temps
from .errors import InputError


def _identity(path: Path) -> tuple[int, int] | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


def path_keys(path: Path) -> set:
    """What makes two paths one file: its real path and, for an existing file, its (device,
    inode) — a hard link or another spelling of the same file shares one of them."""
    return {os.path.realpath(path), _identity(path)} - {None}


def suggest_output(path: str | os.PathLike) -> str:
    """A name beside ``path`` that is not the input: ``x.exr`` → ``x_post.exr``."""
    p = Path(path)
    return str(p.with_name(f"{p.stem}_post{p.suffix or '.exr'}"))


def check_input(path: Path) -> None:
    """InputError unless ``path`` is an existing regular file (a directory is named as one)."""
    if path.is_dir():
        raise InputError(f"{path}: is a directory, not an EXR file; give a file or a frame pattern "
                         f"such as {path / 'render.####.exr'}")
    if not path.exists():
        raise InputError(f"{path}: input frame does not exist; check the path, pattern and --frames")
    if not path.is_file():
        raise InputError(f"{path}: is not a regular file; give the path of an .exr image")


def check_paths(pairs: Sequence[tuple[Path, Path]], output_arg: str | None = None) -> None:
    """Check (input, output) pairs before anything is read or written.

    An output equal to *any* input (a sequence whose output pattern names its own input frames,
    or ``expose -o`` naming one of the frames it reads) is refused: writing it would destroy
    the input, and rerunning would process the result again.
    """
    inputs = {}
    for src, _ in pairs:
        check_input(src)
        inputs.update(dict.fromkeys(path_keys(src), src))
    for _, dst in pairs:
        hit = next((inputs[k] for k in path_keys(dst) if k in inputs), None)
        if hit is not None:
            shown = output_arg or str(dst)
            raise InputError(f"-o {shown}: output {dst} is the input {hit}; writing it would destroy the "
                             f"input (--overwrite does not change that) — choose another output, "
                             f"e.g. -o {suggest_output(shown)}")
        if dst.is_dir():
            raise InputError(f"-o {output_arg or dst}: {dst} is a directory; give an output file name or "
                             "pattern, e.g. out/render.####.exr")


# ----------------------------------------------------------------------------------------------
# The output lock
# ----------------------------------------------------------------------------------------------

def _proc_start(pid: int) -> str | None:
    """Start time of ``pid`` in clock ticks since boot (Linux), to tell a reused pid apart."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            stat = f.read()
    except OSError:
        return None
    # Field 22, counted after the parenthesised command name (which may hold spaces).
    return stat.rsplit(")", 1)[1].split()[19]


def _alive(pid: int, start: str | None) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OSError:
        return False
    now = _proc_start(pid)
    return start is None or now is None or now == start


class OutputLock:
    """``with OutputLock(output_pattern):`` — see the module docstring."""

    def __init__(self, output: str | os.PathLike):
        out = Path(output)
        self.output = str(output)
        self.path = out.with_name(f".{out.name}.lock")
        self.held = False
        self.created_dirs: list[Path] = []

    def _record(self) -> dict:
        pid = os.getpid()
        return {"pid": pid, "host": socket.gethostname(), "proc_start": _proc_start(pid),
                "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "output": self.output}

    def _read(self) -> dict | None:
        try:
            return json.loads(self.path.read_text())
        except FileNotFoundError:
            return None
        except (OSError, ValueError):
            return {}

    def _refuse(self, rec: dict) -> InputError:
        who = f"pid {rec.get('pid')} on {rec.get('host')}, started {rec.get('started')}"
        return InputError(f"-o {self.output}: another clpost run ({who}) is writing this output; wait for it "
                          f"or stop it (a stale lock of a process on another host: remove {self.path})")

    def acquire(self) -> None:
        try:
            # Directories this run creates are removed again at release if nothing was written.
            missing = [d for d in [self.path.parent, *self.path.parent.parents] if not d.exists()]
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.created_dirs = missing
        except OSError as e:
            from .errors import OutputError

            raise OutputError(f"-o {self.output}: cannot create {self.path.parent} ({e.strerror}); "
                              "check the directory is writable") from None
        for _ in range(5):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                rec = self._read()
                if rec is None:
                    continue  # released meanwhile
                if rec and rec.get("host") == socket.gethostname() and isinstance(rec.get("pid"), int):
                    if _alive(rec["pid"], rec.get("proc_start")):
                        raise self._refuse(rec) from None
                elif rec:
                    raise self._refuse(rec) from None
                elif time.time() - self.path.stat().st_mtime < 5:
                    time.sleep(0.2)  # being written by its owner right now
                    continue
                self._take_over(rec)
                continue
            except OSError as e:
                from .errors import OutputError

                raise OutputError(f"-o {self.output}: cannot create the lock {self.path} ({e.strerror}); "
                                  "check the directory is writable") from None
            with os.fdopen(fd, "w") as f:
                json.dump(self._record(), f)
            self.held = True
            return
        raise InputError(f"-o {self.output}: cannot take the lock {self.path}; another run keeps taking it — "
                         "run one clpost per output")

    def _take_over(self, stale: dict) -> None:
        # Rename, not unlink: of two runs taking over the same stale lock only one rename gets it;
        # a run that renamed a fresh lock instead (made meanwhile by the other) puts it back.
        claim = self.path.with_name(f"{self.path.name}.stale-{os.getpid()}")
        try:
            os.rename(self.path, claim)
        except FileNotFoundError:
            return
        try:
            got = json.loads(claim.read_text())
        except (OSError, ValueError):
            got = {}
        if got != stale:
            with contextlib.suppress(OSError):
                os.link(claim, self.path)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(claim)

    def release(self) -> None:
        if not self.held:
            return
        rec = self._read()
        if rec and rec.get("pid") == os.getpid():
            with contextlib.suppress(FileNotFoundError):
                self.path.unlink()
        self.held = False
        for d in self.created_dirs:  # innermost first
            try:
                d.rmdir()
            except OSError:
                break

    def __enter__(self) -> "OutputLock":
        self.acquire()
        return self

    def __exit__(self, *exc) -> None:
        self.release()


@contextlib.contextmanager
def writing(output: str | os.PathLike, dests: Iterable[Path]):
    """Hold the output lock of ``output`` and remove stale temporary files of ``dests`` under it."""
    with OutputLock(output) as lock:
        remove_stale_temps(list(dests))
        yield lock
