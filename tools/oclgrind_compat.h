/* Included into every program built under Oclgrind by tests/test_oclgrind.py
 * (OCLGRIND_BUILD_OPTIONS="-include <this file>"); never part of a clpost kernel.
 *
 * Oclgrind 21.10 (Debian/Ubuntu oclgrind package) evaluates the integer min, max and clamp
 * builtins whose bounds are scalars (min(int16, int), clamp(int16, int, int): the
 * "sgentype" overloads of OpenCL C 1.2 sec. 6.12.3) wrongly: lanes past the first read
 * whatever follows the scalar, so indices computed with them are garbage and the sweep
 * reports out-of-bounds reads that do not exist on a conforming device (the vector-vector
 * overloads and every float overload are right; tests/test_oclgrind.py checks both).
 * These definitions give the scalar overloads a body that splats the scalar and calls the
 * vector overload, so Oclgrind interprets them instead of calling its builtin. */
#define CLPOST_OG_FIX(T, N) \
    T##N __attribute__((overloadable)) min(T##N x, T y) { return min(x, (T##N)(y)); } \
    T##N __attribute__((overloadable)) max(T##N x, T y) { return max(x, (T##N)(y)); } \
    T##N __attribute__((overloadable)) clamp(T##N x, T lo, T hi) { return clamp(x, (T##N)(lo), (T##N)(hi)); }
#define CLPOST_OG_FIX_ALL(T) CLPOST_OG_FIX(T, 2) CLPOST_OG_FIX(T, 3) CLPOST_OG_FIX(T, 4) \
    CLPOST_OG_FIX(T, 8) CLPOST_OG_FIX(T, 16)
CLPOST_OG_FIX_ALL(char)
CLPOST_OG_FIX_ALL(uchar)
CLPOST_OG_FIX_ALL(short)
CLPOST_OG_FIX_ALL(ushort)
CLPOST_OG_FIX_ALL(int)
CLPOST_OG_FIX_ALL(uint)
CLPOST_OG_FIX_ALL(long)
CLPOST_OG_FIX_ALL(ulong)
#undef CLPOST_OG_FIX_ALL
#undef CLPOST_OG_FIX
