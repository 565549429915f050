"""The sensors' Gaussian draws on the compiled path, as source text (build.py writes it into a
sensed scene's module): numpy's own, bit for bit.

sensing/noise.py defines draw k of a stream as element k mod BLOCK of the standard normals
numpy's Generator makes on a Philox bit generator keyed by SeedSequence([seed, stream,
joint, k // BLOCK]). Here the same three steps are written out in numba, on uint64 and
uint32 words: SeedSequence's hash of the entropy words into the Philox key
(numpy/random/bit_generator.pyx), Philox-4x64-10 with numpy's counter and buffer
(philox.h), and the ziggurat of Generator.standard_normal with numpy's tables
(distributions.c; numba ships the same tables). test_draws.py holds them equal to numpy's
draws, tails included. A stream's generator state (DG, a row per stream and joint) is a
cache: a draw of another block, or one behind the state, starts its block afresh, so a
draw stays a function of (seed, stream, joint, index) alone. (The compiled path draws with
these in Python too: sensed.CompiledDraws.)
"""
from __future__ import annotations

from functools import lru_cache


@lru_cache(maxsize=1)
def tables() -> str:
    """The ziggurat's tables and constants as module text (from numba, numpy's own values)."""
    from numba.np.random import _constants as zig
    return "\n".join([
        f"KI = np.array({[int(v) for v in zig.ki_double]!r}, dtype=np.uint64)",
        f"WI = np.array({[float(v) for v in zig.wi_double]!r})",
        f"FI = np.array({[float(v) for v in zig.fi_double]!r})",
        f"NOR_R = {float(zig.ziggurat_nor_r)!r}",
        f"NOR_INV_R = {float(zig.ziggurat_nor_inv_r)!r}", ""])


DRAWS = '''
U32 = np.uint64(0xFFFFFFFF)
U52 = np.uint64(0x000FFFFFFFFFFFFF)
SHIFT16, SHIFT32, SHIFT8, SHIFT11 = np.uint64(16), np.uint64(32), np.uint64(8), np.uint64(11)
ONE, BYTE, ZERO = np.uint64(1), np.uint64(0xFF), np.uint64(0)
PHILOX_M0, PHILOX_M1 = np.uint64(0xD2E7470EE14C6C93), np.uint64(0xCA5A826395121157)
PHILOX_W0, PHILOX_W1 = np.uint64(0x9E3779B97F4A7C15), np.uint64(0xBB67AE8584CAA73B)
INIT_A, MULT_A = np.uint64(0x43b0d7e5), np.uint64(0x931e8875)
INIT_B, MULT_B = np.uint64(0x8b51f9dd), np.uint64(0x58f38ded)
MIX_L, MIX_R = np.uint64(0xca01f9dd), np.uint64(0x4973f715)
BLOCK = 1024
NEVER_BLOCK = np.uint64(0xFFFFFFFFFFFFFFFF)


@njit(cache=True)
def hashmix(value, hash_const):
    """SeedSequence's hashmix on uint32 words (held in uint64): (value, the next constant)."""
    value = (value ^ hash_const) & U32
    hash_const = (hash_const * MULT_A) & U32
    value = (value * hash_const) & U32
    return value ^ (value >> SHIFT16), hash_const


@njit(cache=True)
def mix(x, y):
    result = (MIX_L * x - MIX_R * y) & U32
    return result ^ (result >> SHIFT16)


@njit(cache=True)
def philox_key(seed, stream, joint, block):
    """SeedSequence([seed, stream, joint, block]).generate_state(2, uint64): each entry in
    its uint32 words (0 is one word), the pool of four mixed, two uint64 out."""
    E = np.zeros(8, dtype=np.uint64)
    n = 0
    for value in (np.uint64(seed), np.uint64(stream), np.uint64(joint), np.uint64(block)):
        if value == ZERO:
            E[n] = ZERO
            n += 1
        while value > ZERO:
            E[n] = value & U32
            n += 1
            value = value >> SHIFT32
    pool = np.zeros(4, dtype=np.uint64)
    h = INIT_A
    for i in range(4):
        pool[i], h = hashmix(E[i] if i < n else ZERO, h)
    for s in range(4):
        for d in range(4):
            if s != d:
                mixed, h = hashmix(pool[s], h)
                pool[d] = mix(pool[d], mixed)
    for s in range(4, n):
        for d in range(4):
            mixed, h = hashmix(E[s], h)
            pool[d] = mix(pool[d], mixed)
    out = np.zeros(4, dtype=np.uint64)
    hb = INIT_B
    for i in range(4):
        v = (pool[i] ^ hb) & U32
        hb = (hb * MULT_B) & U32
        v = (v * hb) & U32
        out[i] = v ^ (v >> SHIFT16)
    return out[0] | (out[1] << SHIFT32), out[2] | (out[3] << SHIFT32)


@njit(cache=True)
def mulhilo(a, b):
    """The 128-bit product of two uint64: (high, low) words."""
    a_lo, a_hi, b_lo, b_hi = a & U32, a >> SHIFT32, b & U32, b >> SHIFT32
    ll, lh, hl, hh = a_lo * b_lo, a_lo * b_hi, a_hi * b_lo, a_hi * b_hi
    middle = (ll >> SHIFT32) + (lh & U32) + (hl & U32)
    return hh + (lh >> SHIFT32) + (hl >> SHIFT32) + (middle >> SHIFT32), a * b


@njit(cache=True)
def philox_block(R, r):
    """Philox-4x64-10 of the counter R[r, 4] (then 0, 0, 0) under the key R[r, 2:4], into
    the buffer R[r, 5:9] (numpy's philox_next: the counter stepped first)."""
    c0, c1, c2, c3 = R[r, 4], ZERO, ZERO, ZERO
    k0, k1 = R[r, 2], R[r, 3]
    for rounds in range(10):
        if rounds > 0:
            k0 = k0 + PHILOX_W0
            k1 = k1 + PHILOX_W1
        hi0, lo0 = mulhilo(PHILOX_M0, c0)
        hi1, lo1 = mulhilo(PHILOX_M1, c2)
        c0, c1, c2, c3 = hi1 ^ c1 ^ k0, lo1, hi0 ^ c3 ^ k1, lo0
    R[r, 5], R[r, 6], R[r, 7], R[r, 8] = c0, c1, c2, c3


@njit(cache=True)
def next_uint64(R, r):
    """The next word of the stream whose state is R[r] (numpy's buffer of four a counter)."""
    at = np.int64(R[r, 9])        # (an int64: uint64 + int is a float in numba)
    if at >= 4:
        R[r, 4] = R[r, 4] + ONE
        philox_block(R, r)
        at = 0
    R[r, 9] = np.uint64(at + 1)
    return R[r, 5 + at]


@njit(cache=True)
def next_double(R, r):
    return float(next_uint64(R, r) >> SHIFT11) * (1.0 / 9007199254740992.0)


@njit(cache=True)
def next_normal(R, r):
    """Generator.standard_normal's ziggurat (numpy's random_standard_normal)."""
    while True:
        word = next_uint64(R, r)
        idx = word & BYTE
        word = word >> SHIFT8
        sign = word & ONE
        rabs = (word >> ONE) & U52
        x = float(rabs) * WI[idx]
        if sign == ONE:
            x = -x
        if rabs < KI[idx]:
            return x
        if idx == ZERO:
            while True:
                xx = -NOR_INV_R * log1p(-next_double(R, r))
                yy = -log1p(-next_double(R, r))
                if yy + yy > xx * xx:
                    if ((rabs >> SHIFT8) & ONE) == ONE:
                        return -(NOR_R + xx)
                    return NOR_R + xx
        else:
            if (FI[idx - 1] - FI[idx]) * next_double(R, r) + FI[idx] < exp(-0.5 * x * x):
                return x


@njit(cache=True)
def normal(R, r, seed, stream, joint, index):
    """Draw `index` of (seed, stream, joint): R[r] its stream's cached state (block, draws
    made in it, key, counter, buffer, position in the buffer)."""
    block, at = np.uint64(index // BLOCK), np.uint64(index % BLOCK)
    if R[r, 0] != block or R[r, 1] > at:
        R[r, 0], R[r, 1] = block, ZERO
        R[r, 2], R[r, 3] = philox_key(seed, stream, joint, block)
        R[r, 4], R[r, 9] = ZERO, np.uint64(4)
    while R[r, 1] < at:
        next_normal(R, r)
        R[r, 1] = R[r, 1] + ONE
    R[r, 1] = R[r, 1] + ONE
    return next_normal(R, r)
'''


def source() -> str:
    """The draws' module text: the tables, then the functions (imports are the caller's:
    numpy as np, njit, exp, log1p)."""
    return tables() + DRAWS
