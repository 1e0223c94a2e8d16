"""The one place that creates OpenCL contexts, queues and programs.

Device choice (first match wins):

1. ``device=`` argument / ``--device`` / the ``CLPOST_DEVICE`` environment variable: a
   case-insensitive substring of the platform or device name (``pocl``, ``nvidia``, ``cpu``).
2. Otherwise a GPU device, if any platform offers one.
3. Otherwise the PoCL CPU device (shipped by ``pyopencl[pocl]``), the newest PoCL where there are
   two, else any CPU device. Several devices matching a name (``pocl``) are taken in this order too.

Each candidate must build a one-line kernel first; a device whose compiler fails is skipped and
the next candidate tried. Why: the PoCL 3.0 that pip ships links LLVM 14, which does not know
CPUs newer than it (e.g. AMD Zen 5 reports "unknown target CPU 'generic'"), while Debian/Ubuntu's
``pocl-opencl-icd`` picks a known kernel-library CPU and works; with both installed they show up
as two platforms of the same name.

Platforms are selected by name, never by index: installing a second OpenCL driver reorders them.

Program cache: programs are built once per process (keyed by device, full source and options)
and cached on disk between runs by the driver. On PoCL, pyopencl leaves disk caching to PoCL;
we point ``POCL_CACHE_DIR`` at a per-user directory (``$XDG_CACHE_HOME/clpost/pocl``) unless the
user set it (build times: docs/measurements.md#host-work).

Build options (:data:`BUILD_OPTIONS`): OpenCL C 1.2 and nothing that relaxes IEEE semantics —
no ``-cl-fast-relaxed-math``, ``-cl-finite-math-only`` or ``-cl-denorms-are-zero``: stages rely on
``+inf`` depths, tiny luminances (1e-6) and exact ``isfinite`` checks.
"""
from __future__ import annotations

import contextlib
import functools
import mmap
import os
import re
import threading
import weakref
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path

from .errors import KernelBuildError, OpenCLUnavailableError


def _cache_root() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "clpost"


# PoCL reads this when its platform initialises, i.e. on first use of pyopencl: set it first.
os.environ.setdefault("POCL_CACHE_DIR", str(_cache_root() / "pocl"))

import numpy as np  # noqa: E402
import pyopencl as cl  # noqa: E402

BUILD_OPTIONS: tuple[str, ...] = ("-cl-std=CL1.2", "-cl-kernel-arg-info")
"""Options every program is built with (see the module docstring for what is deliberately absent;
``-cl-kernel-arg-info`` lets :func:`typed_kernel` read the argument types)."""

_SCALAR_DTYPES = {
    "char": np.int8, "uchar": np.uint8, "short": np.int16, "ushort": np.uint16,
    "int": np.int32, "uint": np.uint32, "long": np.int64, "ulong": np.uint64,
    "float": np.float32, "double": np.float64,
}


def typed_kernel(kernel: "cl.Kernel") -> "cl.Kernel":
    """Declare ``kernel``'s scalar argument types to pyopencl (``set_scalar_arg_dtypes``), read from
    the program's argument info. Why: without them pyopencl's ``set_args`` inspects every argument
    generically, 20–50× slower per call than typed — it was the largest host cost of a frame
    (docs/measurements.md#host-work). Kernels whose argument info the driver cannot give (or with
    vector-typed scalars) are left as they are: correct, only slower to launch."""
    info = cl.kernel_arg_info
    dtypes = []
    try:
        for i in range(kernel.num_args):
            name = kernel.get_arg_info(i, info.TYPE_NAME).strip().rstrip("\0")
            qual = kernel.get_arg_info(i, info.ADDRESS_QUALIFIER)
            if qual != cl.kernel_arg_address_qualifier.PRIVATE or name.endswith("*"):
                dtypes.append(None)          # buffers and __local memory
            elif name in _SCALAR_DTYPES:
                dtypes.append(_SCALAR_DTYPES[name])
            else:
                return kernel                # images, samplers, vector scalars: leave untyped
    except cl.Error:
        return kernel
    kernel.set_scalar_arg_dtypes(dtypes)
    kernel._clpost_dtypes = dtypes
    return kernel


def private_kernel(kernel: "cl.Kernel") -> "cl.Kernel":
    """A new ``cl.Kernel`` of the same program and function as ``kernel``, typed like it: a kernel
    object holds its arguments, so a recorded launch (:mod:`clpost.runtime_record`) owns one whose
    arguments are set once."""
    clone = cl.Kernel(kernel.program, kernel.function_name)
    dtypes = getattr(kernel, "_clpost_dtypes", None)
    if dtypes is None:
        return typed_kernel(clone)
    clone.set_scalar_arg_dtypes(dtypes)
    clone._clpost_dtypes = dtypes
    return clone

class Captured:
    """A kernel as a stage sees it through a :class:`clpost.runtime_record.Recorder`: ``set_args``
    / ``set_arg`` are kept for the next launch, the shared kernel object itself is not touched.
    A stage's plan-time objects may keep one (e.g. in :meth:`Runtime.cached`): :meth:`Runtime.launch`
    then sets the kept arguments and launches the kernel."""

    __slots__ = ("kernel", "args")

    def __init__(self, kernel: "cl.Kernel") -> None:
        self.kernel = kernel
        self.args: list = []

    def set_args(self, *args) -> None:
        self.args = list(args)

    def set_arg(self, index: int, value) -> None:
        self.args += [None] * (index + 1 - len(self.args))
        self.args[index] = value

    def __getattr__(self, name):  # function_name, num_args, program …
        return getattr(self.kernel, name)


INSTALL_HINT = (
    "install the PoCL CPU driver with `pip install 'pyopencl[pocl]'` (Linux) — on CPUs newer than "
    "its LLVM knows, Debian/Ubuntu's `apt-get install pocl-opencl-icd` — or your GPU vendor's OpenCL driver"
)
_SMOKE_KERNEL = "__kernel void clpost_smoke(__global float *a) { a[get_global_id(0)] *= 2.0f; }"
_smoke_results: dict[int, str | None] = {}


@functools.lru_cache(maxsize=None)
def kernels_dir() -> Path:
    """Directory holding the ``.cl`` sources: packaged as ``clpost/kernels`` in a wheel,
    ``<repo>/kernels`` in a source checkout."""
    here = Path(__file__).resolve().parent
    for cand in (here / "kernels", here.parent / "kernels"):
        if (cand / "common.cl").is_file():
            return cand
    raise OpenCLUnavailableError(
        f"clpost's OpenCL sources (kernels/*.cl) were not found beside {here}; reinstall clpost"
    )


@functools.lru_cache(maxsize=None)
def kernel_source(name: str) -> str:
    """Text of ``kernels/<name>.cl`` (read once per process: stages ask for it every frame)."""
    return _read_source(kernels_dir() / f"{name}.cl")


@functools.lru_cache(maxsize=None)
def _read_source(path: Path) -> str:
    try:
        return path.read_text()
    except FileNotFoundError:
        raise KernelBuildError(f"kernel source {path} is missing; reinstall clpost") from None


def _describe(dev: "cl.Device") -> str:
    return f"{dev.platform.name.strip()} / {dev.name.strip()}"


def list_devices() -> list["cl.Device"]:
    """All OpenCL devices of all platforms (empty if there is no platform)."""
    try:
        platforms = cl.get_platforms()
    except cl.Error:
        return []
    devs = []
    for p in platforms:
        try:
            devs.extend(p.get_devices())
        except cl.Error:
            continue
    return devs


def _compiler_problem(dev: "cl.Device") -> str | None:
    """None if ``dev`` builds a trivial kernel, else the first line of the compiler's complaint."""
    key = dev.int_ptr
    if key not in _smoke_results:
        try:
            cl.Program(cl.Context([dev]), _SMOKE_KERNEL).build()
            _smoke_results[key] = None
        except cl.Error as exc:
            lines = [ln.strip() for ln in str(exc).splitlines() if "error" in ln.lower()]
            _smoke_results[key] = (lines[-1] if lines else str(exc).splitlines()[0])[:200]
    return _smoke_results[key]


def _rank(dev: "cl.Device") -> tuple:
    """Sort key of the candidates (module docstring): a GPU, then PoCL's CPU device — the newest
    PoCL first where two are installed (pip's 3.0 beside a distribution's 5.0 ran the worst case
    2.8× slower on the same 16 cores: its LLVM 14 targets an older CPU; docs/benchmarks.md,
    "Two PoCLs on one machine, and huge pages on 16 cores") — then any other CPU device."""
    if dev.type & cl.device_type.GPU:
        return (0,)
    if dev.type & cl.device_type.CPU:
        if _is_pocl(dev):
            m = re.search(r"pocl (\d+)\.(\d+)", dev.platform.version.lower())
            return (1, -int(m.group(1)), -int(m.group(2))) if m else (1, 0, 0)
        return (2,)
    return (3,)


def _is_pocl(dev: "cl.Device") -> bool:
    name = dev.platform.name.lower()
    return "portable computing language" in name or "pocl" in name


def choose_device(spec: str | None = None) -> "cl.Device":
    """Pick a device per the rules in the module docstring."""
    spec = spec if spec is not None else os.environ.get("CLPOST_DEVICE") or None
    devs = list_devices()
    if not devs:
        raise OpenCLUnavailableError(f"no OpenCL platform found: {INSTALL_HINT}")
    if spec:
        s = spec.lower()
        # The version string names the implementation ("PoCL 3.1", "CUDA 13.0") where the
        # platform name does not ("Portable Computing Language"), so `pocl` matches too.
        candidates = [d for d in devs if s in d.platform.name.lower() or s in d.name.lower()
                      or s in d.platform.version.lower()]
        if not candidates:
            have = "; ".join(_describe(d) for d in devs)
            raise OpenCLUnavailableError(
                f"--device/CLPOST_DEVICE={spec!r} matches no OpenCL device (have: {have}); "
                "give a substring of one of these names"
            )
    else:
        candidates = devs
    candidates = sorted(candidates, key=_rank)
    problems = []
    for d in candidates:
        why = _compiler_problem(d)
        if why is None:
            return d
        problems.append(f"{_describe(d)} ({d.platform.version.strip()}): {why}")
    raise OpenCLUnavailableError(
        "no OpenCL device can build kernels — " + "; ".join(problems) + f". Fix: {INSTALL_HINT}"
    )


def round_up(n: int, multiple: int) -> int:
    """``n`` rounded up to a whole number of ``multiple`` (a launch's global size in work-groups)."""
    return -(-int(n) // int(multiple)) * int(multiple)


def launch_sizes(global_size, local_size=None) -> tuple[tuple[int, ...], tuple[int, ...] | None]:
    """(global, local) as int tuples, the global size rounded up to whole work-groups."""
    glob = tuple(int(g) for g in global_size)
    if local_size is None:
        return glob, None
    local = tuple(int(v) for v in local_size)
    return tuple(round_up(g, l) for g, l in zip(glob, local)), local


CONSTANT_CACHE_ENTRIES = 256
"""Read-only buffers :meth:`Runtime.constant` keeps per runtime (least recently used dropped):
enough for every table of a plan, bounded when an animated parameter makes a new table per frame."""


@dataclass
class Runtime:
    """A context and an in-order profiling queue on one device, and the device-work toolkit every
    stage uses (plan-time work done once, call-time work per frame):

    - :meth:`program` / :meth:`kernel` / :meth:`kernels`: programs built once per (source,
      defines); ``cl.Kernel`` objects cached per (program, kernel name) and thread — a kernel
      object holds its arguments, so two threads never share one;
    - :meth:`empty`: a device buffer (on PoCL's CPU device in transparent huge pages from
      2 MiB on, :attr:`huge_pages`); :meth:`constant`: a read-only buffer uploaded once per
      content key;
    - :meth:`scratch`: a work buffer per (owner, name), reused across frames while its shape and
      dtype stay the same; :meth:`cached`: a plan-time object per (owner, name) rebuilt only when
      its structural key changes;
    - :meth:`launch`: enqueue with the global size rounded up to whole work-groups;
      :meth:`launch_once` for plan-time work; :meth:`copy` for a per-frame transfer. Plans run
      gather stages through a :class:`clpost.runtime_record.Recorder` with the same methods, which
      records these launches and copies to replay them on the next frames.
    """

    device: "cl.Device"
    context: "cl.Context" = field(init=False)
    queue: "cl.CommandQueue" = field(init=False)
    _programs: dict = field(default_factory=dict, init=False, repr=False)
    _local: threading.local = field(default_factory=threading.local, init=False, repr=False)
    _constants: "OrderedDict" = field(default_factory=lambda: OrderedDict(), init=False, repr=False)
    _scratch: "weakref.WeakKeyDictionary" = field(default_factory=lambda: weakref.WeakKeyDictionary(),
                                                  init=False, repr=False)
    _transfer: tuple | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        self.context = cl.Context([self.device])
        self.queue = cl.CommandQueue(
            self.context, properties=cl.command_queue_properties.PROFILING_ENABLE
        )

    @property
    def name(self) -> str:
        return _describe(self.device)

    @property
    def discrete(self) -> bool:
        """Whether the device is a GPU with memory of its own (no ``CL_DEVICE_HOST_UNIFIED_MEMORY``):
        a frame's transfers then cross a bus and are worth overlapping with the kernels of other
        frames (:meth:`clpost.plan.Plan.submit`). On a CPU device or an integrated GPU a transfer
        is a copy in the same memory the kernels use, so staging it costs bandwidth and gains
        nothing."""
        if not self.device.type & cl.device_type.GPU:
            return False
        try:
            return not self.device.host_unified_memory
        except cl.Error:  # the query is deprecated since OpenCL 2.0; a driver may refuse it
            return True

    def transfer_queues(self) -> tuple["cl.CommandQueue", "cl.CommandQueue"]:
        """(upload, download): two more in-order profiling queues in the runtime's context, made
        on first use, for :meth:`clpost.plan.Plan.submit`'s transfers, which run beside the
        kernels of :attr:`queue` (a GPU's copy engines work while its cores compute). Commands of
        different queues are ordered only by the events they wait for."""
        if self._transfer is None:
            props = cl.command_queue_properties.PROFILING_ENABLE
            self._transfer = (cl.CommandQueue(self.context, properties=props),
                              cl.CommandQueue(self.context, properties=props))
        return self._transfer

    @property
    def wide(self) -> bool:
        """Whether kernels with a wide form take 16 pixels per work-item (CPUs: the lanes of SIMD
        registers) or one (GPUs: a warp's loads coalesce; groups of a tile's pixels): the fused
        pointwise kernels (:func:`clpost.codegen.vector_path`), astigmatism's gather and dof's gather
        (:func:`clpost.stages.dof_cl.gather_vector_width`)."""
        return not (self.device.type & cl.device_type.GPU)

    @staticmethod
    @contextlib.contextmanager
    def forced_width(wide: bool):
        """Every runtime's :attr:`wide` reads ``wide`` inside the block: the other form of the
        kernels that have two, on this device (a GPU's one-pixel forms timed or checked on a CPU,
        or the reverse: tools/gpu_forms.py, tools/oclgrind_sweep.py). Plans built inside keep the
        form they were built with."""
        saved = Runtime.wide
        Runtime.wide = property(lambda self: wide)
        try:
            yield
        finally:
            Runtime.wide = saved

    def program(self, source: str, name: str, defines: dict[str, object] | None = None) -> "cl.Program":
        """Build ``source`` once per (source, defines); ``name`` is used in error messages."""
        opts = list(BUILD_OPTIONS)
        for k, v in sorted((defines or {}).items()):
            opts.append(f"-D{k}={v}")
        key = (source, tuple(opts))
        prog = self._programs.get(key)
        if prog is None:
            try:
                prog = cl.Program(self.context, source).build(options=opts)
            except cl.RuntimeError as exc:
                raise KernelBuildError(
                    f"OpenCL kernel '{name}' failed to build on {self.name} with options "
                    f"{' '.join(opts)}:\n{exc}"
                ) from None
            self._programs[key] = prog
        return prog

    def kernel(self, source: str, name: str, defines: dict[str, object] | None = None,
               program: str | None = None) -> "cl.Kernel":
        """The ``cl.Kernel`` ``name`` of ``source`` built with ``defines``, one object per
        (program, name) and thread; ``program`` names the program in build errors (default
        ``name``). Set its arguments right before each launch."""
        cache = self._local.__dict__.setdefault("kernels", {})
        key = (source, name, tuple(sorted(defines.items())) if defines else ())
        knl = cache.get(key)
        if knl is None:
            prog = self.program(source, program or name, defines)
            knl = cache[key] = typed_kernel(cl.Kernel(prog, name))
        return knl

    def kernels(self, source: str, program: str, defines: dict[str, object] | None = None) -> dict:
        """Every kernel of ``source`` by name (cached as :meth:`kernel`)."""
        prog = self.program(source, program, defines)
        return {k.function_name: self.kernel(source, k.function_name, defines, program)
                for k in prog.all_kernels()}

    def constant(self, host, key=None) -> "cl.Buffer":
        """A read-only device copy of ``host`` (an array, or a callable making it), uploaded once
        per content key and shared by everything that asks for the same content. ``key``: any
        hashable that determines the content (e.g. the structural parameters the table is built
        from; a callable ``host`` is called only when the key is new); default: the array's
        dtype, shape and bytes — fine for small tables, pass a key for large ones."""
        if key is None:
            if callable(host):
                raise TypeError("Runtime.constant: a callable needs a key")
            a = np.ascontiguousarray(host)
            key = (a.dtype.str, a.shape, a.tobytes())
        buf = self._constants.get(key)
        if buf is not None:
            self._constants.move_to_end(key)
            return buf
        a = np.ascontiguousarray(host() if callable(host) else host)
        if a.nbytes == 0:
            a = np.zeros(1, a.dtype if a.dtype.itemsize >= 4 else np.float32)
        mf = cl.mem_flags
        buf = cl.Buffer(self.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a)
        self._constants[key] = buf
        while len(self._constants) > CONSTANT_CACHE_ENTRIES:
            self._constants.popitem(last=False)
        return buf

    def scratch(self, owner, name: str, shape: tuple[int, ...], dtype=np.float32) -> "cl.Buffer":
        """Work buffer ``name`` of ``owner`` (e.g. a stage; held weakly) with ``shape``/``dtype``:
        the same buffer every frame while they stay the same, a new one when they change."""
        shape = tuple(int(v) for v in shape)
        bufs = self._scratch.setdefault(owner, {})
        want = (shape, np.dtype(dtype).str)
        have = bufs.get(name)
        if have is None or have[0] != want:
            have = bufs[name] = (want, self.empty(shape, dtype))
        return have[1]

    def cached(self, owner, name: str, key, make):
        """Plan-time object ``name`` of ``owner`` (held weakly): ``make()`` when ``key`` (the
        structure it depends on: camera fields, size, quality) differs from last call's, else the
        object made then. For tables and launch plans a stage would otherwise rebuild per frame."""
        slot = self._scratch.setdefault(owner, {})
        have = slot.get(("cached", name))
        if have is None or have[0] != key:
            have = slot[("cached", name)] = (key, make())
        return have[1]

    def launch(self, kernel: "cl.Kernel", global_size, local_size=None, *args) -> "cl.Event":
        """Enqueue ``kernel`` (with ``args`` set first, if given) over ``global_size`` rounded up
        to whole ``local_size`` work-groups (the kernel guards its bounds). Why round: left to
        itself PoCL picks tiny work-groups for sizes like 706×426 and runs many times slower
        (docs/measurements.md#kernel-forms-on-pocl)."""
        if type(kernel) is Captured:
            args, kernel = args or tuple(kernel.args), kernel.kernel
        if args:
            kernel.set_args(*args)
        glob, local_size = launch_sizes(global_size, local_size)
        return cl.enqueue_nd_range_kernel(self.queue, kernel, glob, local_size)

    def launch_once(self, kernel: "cl.Kernel", global_size, local_size=None, *args) -> "cl.Event":
        """:meth:`launch` for plan-time work (a table computed on the device once per camera and
        size): the same now, but a recording (:class:`clpost.runtime_record.Recorder`) does not
        replay it with the frame's launches."""
        return self.launch(kernel, global_size, local_size, *args)

    def copy(self, dst, src, blocking: bool = False) -> "cl.Event":
        """Enqueue a copy between a device buffer and a host array (or two buffers): a frame's
        per-frame transfer, which a recording replays."""
        return cl.enqueue_copy(self.queue, dst, src, is_blocking=blocking)

    def pinned_empty(self, shape: tuple[int, ...], dtype=np.float32, queue=None) -> np.ndarray:
        """A host array in page-locked memory (an ``ALLOC_HOST_PTR`` buffer, mapped): a discrete
        GPU copies it by DMA at the bus's rate instead of staging pageable memory through the
        driver (H100, PCIe: 52 vs 13 GB/s, ``tools/transfer_bench.py``). Fill a frame's arrays
        in it (or pass it as ``Plan.run(out=...)``) to keep transfers off the frame time. The
        array keeps its buffer mapped while it lives. ``queue``: the queue that maps it (default
        the compute queue, where the map waits for every command before it)."""
        nbytes = max(int(np.prod(shape)) * np.dtype(dtype).itemsize, 4)
        buf = cl.Buffer(self.context, cl.mem_flags.READ_WRITE | cl.mem_flags.ALLOC_HOST_PTR, nbytes)
        arr, _ = cl.enqueue_map_buffer(queue or self.queue, buf, cl.map_flags.READ | cl.map_flags.WRITE, 0,
                                       tuple(shape), dtype, is_blocking=True)
        return arr

    @functools.cached_property
    def huge_pages(self) -> bool:
        """Whether :meth:`empty` backs its large buffers with transparent huge pages: PoCL's CPU
        device (its buffers are host memory, and a ``USE_HOST_PTR`` buffer is the host array
        itself) on Linux with 2 MiB huge pages, unless ``CLPOST_HUGE_PAGES=0``. Why: PoCL
        allocates buffers in 4 KiB pages, and every gather and row pass here walks several
        planes of tens of MB at once, so a tap's loads touch dozens of pages; on the project's
        (virtualised) 2-core box the page walks cost the plans a large part of their time. Same
        kernels, same output bits (docs/benchmarks.md, "Huge pages for the CPU device's
        buffers"; ``tools/ab_kernel.py --pages`` measures it)."""
        if os.environ.get("CLPOST_HUGE_PAGES", "1") == "0" or not hasattr(mmap, "MADV_HUGEPAGE"):
            return False
        try:  # the kernel's huge page size: 2 MiB on x86-64 (other sizes: plain buffers)
            pmd = int(Path("/sys/kernel/mm/transparent_hugepage/hpage_pmd_size").read_text())
        except (OSError, ValueError):
            return False
        return (pmd == HUGE_PAGE and bool(self.device.type & cl.device_type.CPU)
                and "Portable Computing Language" in self.device.platform.name)

    def host_array(self, name: str, shape: tuple[int, ...], dtype=np.float32) -> np.ndarray:
        """The host array a stage downloads the output frame's buffer ``name`` into (a resampling
        stage's ``depth``, ``velocity``): a new one here; while a plan records the stage, the
        array the caller gave for it (``Plan.run(out={...})``, :class:`clpost.runtime_record.Recorder`)."""
        return np.empty(shape, dtype)

    def empty(self, shape: tuple[int, ...], dtype=np.float32) -> "cl.Buffer":
        nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
        if nbytes >= HUGE_PAGE and self.huge_pages:
            host = huge_page_array(nbytes)
            if host is not None:
                buf = _HostBuffer(self.context, cl.mem_flags.READ_WRITE | cl.mem_flags.USE_HOST_PTR,
                                  hostbuf=host[:nbytes])
                # the memory is the buffer's: freed only after every command queued before the
                # buffer's release has run (pyopencl drops its reference with the buffer object)
                weakref.finalize(buf, _finish_queues, self, host).atexit = False
                return buf
        return cl.Buffer(self.context, cl.mem_flags.READ_WRITE, size=max(nbytes, 4))


class _HostBuffer(cl.Buffer):
    """A ``USE_HOST_PTR`` buffer of :meth:`Runtime.empty` (a Python subclass: it takes weak
    references, for the finalizer that keeps its memory until the queues are done with it)."""


def _finish_queues(rt: Runtime, host) -> None:
    """A huge-page buffer's finalizer: wait for the runtime's queues; ``host`` (its memory) is
    freed when this returns."""
    for q in (rt.queue, *(rt._transfer or ())):
        q.finish()


HUGE_PAGE = 2 << 20
"""Bytes of an x86-64 transparent huge page; :meth:`Runtime.empty` backs buffers of at least this
with them where the kernel's page size is this (:attr:`Runtime.huge_pages`)."""


def huge_page_array(nbytes: int) -> np.ndarray | None:
    """``nbytes`` (rounded up to whole huge pages) of zeroed anonymous memory as a uint8 array,
    aligned to :data:`HUGE_PAGE` and advised for transparent huge pages (``MADV_HUGEPAGE``: the
    kernel's default THP mode, ``madvise``, gives them only to advised memory); None where the
    mapping or the advice fails (the caller falls back to a plain buffer). Pages are faulted in
    by their first use, as PoCL's own allocations are; where no huge page is free the kernel
    gives 4 KiB ones, as before."""
    size = -(-nbytes // HUGE_PAGE) * HUGE_PAGE
    try:
        m = mmap.mmap(-1, size + HUGE_PAGE, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
        m.madvise(mmap.MADV_HUGEPAGE)
    except (OSError, ValueError, AttributeError):
        return None
    whole = np.frombuffer(m, np.uint8)  # holds the mapping while any view of it lives
    off = (-whole.ctypes.data) % HUGE_PAGE
    return whole[off:off + size]


_runtimes: dict[int, Runtime] = {}
_lock = threading.Lock()


def get_runtime(device: str | None = None) -> Runtime:
    """The process-wide :class:`Runtime` for a device spec (created on first use)."""
    dev = choose_device(device)
    key = dev.int_ptr
    with _lock:
        rt = _runtimes.get(key)
        if rt is None:
            rt = _runtimes[key] = Runtime(dev)
        return rt


def event_ms(event: "cl.Event") -> float:
    """Device time of a profiled event in milliseconds."""
    return (event.profile.end - event.profile.start) * 1e-6
