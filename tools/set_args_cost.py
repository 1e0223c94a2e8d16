"""Host cost of pyopencl's ``Kernel.set_args``, untyped vs with scalar types declared.

Thread CPU µs per call on the default OpenCL device, for a 6-argument kernel (two buffers, two
ints, two floats) — why :func:`clpost.runtime.typed_kernel` declares every kernel's scalar types.

    python tools/set_args_cost.py
"""
import time

import numpy as np
import pyopencl as cl

from clpost.runtime import get_runtime, typed_kernel

SOURCE = "__kernel void k(__global float *a, __global float *b, int w, int h, float x, float y) {}"


def per_call_us(fn, n: int = 2000) -> float:
    for _ in range(50):
        fn()
    t0 = time.thread_time()
    for _ in range(n):
        fn()
    return (time.thread_time() - t0) / n * 1e6


def main() -> int:
    rt = get_runtime()
    prog = rt.program(SOURCE, "k")
    a, b = rt.empty((16,)), rt.empty((16,))
    args = (a, b, np.int32(3), np.int32(4), np.float32(1), np.float32(2))
    untyped = cl.Kernel(prog, "k")
    typed = typed_kernel(cl.Kernel(prog, "k"))
    print(f"device: {rt.name}")
    print(f"untyped set_args: {per_call_us(lambda: untyped.set_args(*args)):.2f} µs/call")
    print(f"typed set_args:   {per_call_us(lambda: typed.set_args(*args)):.2f} µs/call")
    print(f"enqueue_nd_range_kernel: {per_call_us(lambda: cl.enqueue_nd_range_kernel(rt.queue, typed, (16,), None)):.2f} µs/call")
    rt.queue.finish()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
