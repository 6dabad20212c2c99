"""NumPy's per-replicate generators, vectorised: the first draws of ``np.random.default_rng([*entropy, r])`` for
millions of replicates ``r`` at once, bit for bit.

A sweep draws replicate r's command from ``np.random.default_rng([seed, 2, r])`` (so replicate r gets the same
command in every cell, and a plan does not depend on how many replicates it has). Building one generator costs
~20 microseconds, so a plan of 2e7 replicates spent ~7 minutes there. The generator is fixed by published
algorithms that NumPy keeps stable (NEP 19: the bit generators' streams and the seeding do not change between
versions): :class:`numpy.random.SeedSequence` hashes the entropy words into a pool and expands it into the
seed of :class:`numpy.random.PCG64` (a 128-bit LCG with an XSL-RR output), and ``Generator.uniform(lo, hi)`` is
``lo + (hi - lo) * u`` with u the top 53 bits of one 64-bit output. :func:`uniform_draws` runs those steps on
arrays (uint32 hashing, 128-bit arithmetic on pairs of uint64), a replicate per element.

The definition stays NumPy's: :func:`uniform_draws` compares its values for a spread of replicates with
``default_rng`` itself on every call, and where any differs (a NumPy that changed, a build whose ``uniform``
fuses its multiply-add) it draws every replicate with ``default_rng`` instead, as before.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence

import numpy as np

__all__ = ["CHECKED_REPLICATES", "first_doubles", "reference_draws", "uniform_draws"]

CHECKED_REPLICATES = 64
"""Replicates (spread evenly, first and last included) whose vectorised draws are compared with NumPy's own
generator on every :func:`uniform_draws` call (~20 microseconds each)."""

_BLOCK = 1 << 13  # replicates per vectorised block: its temporaries stay in cache (docs/benchmarks_history.md)

# SeedSequence (numpy/random/bit_generator.pyx): pool of 4 uint32 words, hash and mix constants.
_POOL = 4
_INIT_A, _MULT_A = 0x43B0D7E5, 0x931E8875
_INIT_B, _MULT_B = 0x8B51F9DD, 0x58F38DED
_MIX_L, _MIX_R = 0xCA01F9DD, 0x4973F715
_XSHIFT = 16
_MASK32 = 0xFFFFFFFF
# PCG64 (numpy/random/src/pcg64): the 128-bit LCG multiplier, high and low words.
_MUL_HI, _MUL_LO = 2549297995355413924, 4865540595714422341


def _words(n: int) -> list[int]:
    """An entropy integer as SeedSequence's little-endian uint32 words (0 is one word)."""
    if n < 0:
        raise ValueError(f"entropy must be >= 0, got {n}")
    out = [n & _MASK32]
    n >>= 32
    while n:
        out.append(n & _MASK32)
        n >>= 32
    return out


def _hash_consts(start: int, mult: int, count: int) -> list[tuple[np.uint32, np.uint32]]:
    """(xor, multiply) constants of each of ``count`` hashes: the hash constant before the hash and after it
    advances by ``mult`` (it advances once per hash, whatever the data, so it is the same for every row)."""
    out, h = [], start
    for _ in range(count):
        after = (h * mult) & _MASK32
        out.append((np.uint32(h), np.uint32(after)))
        h = after
    return out


def _pools(entropy: np.ndarray) -> list[np.ndarray]:
    """SeedSequence.mix_entropy of each row of ``entropy`` ((n, L) uint32): the 4 pool words, (n,) uint32 each."""
    n, length = entropy.shape
    calls = _POOL + _POOL * (_POOL - 1) + max(length - _POOL, 0) * _POOL
    consts = iter(_hash_consts(_INIT_A, _MULT_A, calls))

    def hashmix(value):
        xor, mul = next(consts)
        value = (value ^ xor) * mul
        return value ^ (value >> np.uint32(_XSHIFT))

    def mix(x, y):
        r = np.uint32(_MIX_L) * x - np.uint32(_MIX_R) * y
        return r ^ (r >> np.uint32(_XSHIFT))

    zero = np.zeros(n, np.uint32)
    pool = [hashmix(entropy[:, i] if i < length else zero) for i in range(_POOL)]
    for src in range(_POOL):
        for dst in range(_POOL):
            if src != dst:
                pool[dst] = mix(pool[dst], hashmix(pool[src]))
    for src in range(_POOL, length):
        for dst in range(_POOL):
            pool[dst] = mix(pool[dst], hashmix(entropy[:, src]))
    return pool


def _state_words(pool: list[np.ndarray]) -> list[np.ndarray]:
    """SeedSequence.generate_state(4, np.uint64): four (n,) uint64 words from the pool."""
    words32 = []
    for i, (xor, mul) in enumerate(_hash_consts(_INIT_B, _MULT_B, 8)):
        v = (pool[i % _POOL] ^ xor) * mul
        words32.append(v ^ (v >> np.uint32(_XSHIFT)))
    return [words32[2 * i].astype(np.uint64) | (words32[2 * i + 1].astype(np.uint64) << np.uint64(32))
            for i in range(4)]


def _step(hi, lo, inc_hi, inc_lo):
    """One PCG64 step: state * multiplier + inc (mod 2**128), on (high, low) pairs of (n,) uint64."""
    m, s = np.uint64(_MASK32), np.uint64(32)
    b0, b1 = np.uint64(_MUL_LO & _MASK32), np.uint64(_MUL_LO >> 32)
    a0, a1 = lo & m, lo >> s
    p00, p01, p10 = a0 * b0, a0 * b1, a1 * b0
    mid = (p00 >> s) + (p01 & m) + (p10 & m)
    lo_hi = a1 * b1 + (p01 >> s) + (p10 >> s) + (mid >> s)  # the high word of lo * multiplier's low word
    new_hi = lo_hi + lo * np.uint64(_MUL_HI) + hi * np.uint64(_MUL_LO)
    new_lo = lo * np.uint64(_MUL_LO)
    out_lo = new_lo + inc_lo
    return new_hi + inc_hi + (out_lo < new_lo), out_lo


def _doubles(entropy: np.ndarray, count: int) -> np.ndarray:
    """(n, count) float64: the first ``count`` ``next_double`` of PCG64(SeedSequence(row)) for each entropy row."""
    seed_hi, seed_lo, inc_hi, inc_lo = _state_words(_pools(entropy))
    # pcg_setseq_128_srandom_r: inc = (initseq << 1) | 1; state = 0; step; state += initstate; step
    inc_hi, inc_lo = (inc_hi << np.uint64(1)) | (inc_lo >> np.uint64(63)), (inc_lo << np.uint64(1)) | np.uint64(1)
    lo = inc_lo + seed_lo  # the first step from state 0 leaves inc
    hi = inc_hi + seed_hi + (lo < inc_lo)
    hi, lo = _step(hi, lo, inc_hi, inc_lo)
    out = np.empty((entropy.shape[0], count))
    for j in range(count):
        hi, lo = _step(hi, lo, inc_hi, inc_lo)  # random_r steps, then outputs the new state
        x = hi ^ lo
        rot = hi >> np.uint64(58)
        x = (x >> rot) | (x << ((np.uint64(64) - rot) & np.uint64(63)))  # rotr64 (a rotation by 0 is x)
        out[:, j] = (x >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0)
    return out


def first_doubles(entropy: Sequence[int], reps, count: int) -> np.ndarray:
    """(len(reps), count) float64: ``np.random.default_rng([*entropy, r]).random(count)`` for each replicate r.

    The vectorised generators :func:`uniform_draws` draws with (SeedSequence, PCG64, ``next_double``), for any
    replicates, unchecked: :func:`uniform_draws` is the call that compares them with NumPy's own.

    Args:
      entropy: the non-negative integers before the replicate in the seed list (e.g. ``[seed, 2]``).
      reps: (n,) replicate numbers in [0, 2**32).
      count: doubles per replicate (>= 0).

    Example:
      >>> import numpy as np
      >>> got = first_doubles([7, 2], [0, 4_000_000_000], 2)
      >>> bool(np.all(got[1] == np.random.default_rng([7, 2, 4_000_000_000]).random(2)))
      True
    """
    r = np.asarray(reps, np.int64).reshape(-1)
    if r.size and (r.min() < 0 or r.max() >= 2**32):
        raise ValueError(f"replicates must be in [0, 2**32), got {r.min()} .. {r.max()}")
    prefix = [w for e in entropy for w in _words(int(e))]
    rows = np.empty((r.size, len(prefix) + 1), np.uint32)
    rows[:, :-1] = prefix
    rows[:, -1] = r
    with np.errstate(over="ignore"):
        return _doubles(rows, int(count))


def reference_draws(entropy: Sequence[int], ranges: Sequence[tuple[float, float]], reps,
                    on_replicate: Callable[[int], None] | None = None) -> np.ndarray:
    """(len(reps), K) float64: ``rng.uniform(lo, hi)`` for each (lo, hi) of ``ranges`` in turn, with
    ``rng = np.random.default_rng([*entropy, r])`` for each replicate r of ``reps`` (the definition, one generator
    per replicate). ``on_replicate(i)`` is called after the i-th row (progress)."""
    reps = list(reps)
    out = np.empty((len(reps), len(ranges)))
    for i, r in enumerate(reps):
        rng = np.random.default_rng([*entropy, int(r)])
        out[i] = [rng.uniform(lo, hi) for lo, hi in ranges]
        if on_replicate is not None:
            on_replicate(i)
    return out


def uniform_draws(entropy: Sequence[int], ranges: Sequence[tuple[float, float]], num_reps: int,
                  on_block: Callable[[int], None] | None = None,
                  on_replicate: Callable[[int], None] | None = None) -> np.ndarray:
    """(num_reps, K) float64: :func:`reference_draws` for replicates ``0 .. num_reps - 1``, vectorised.

    Args:
      entropy: the non-negative integers before the replicate in the seed list (e.g. ``[seed, 2]``).
      ranges: K (lo, hi) pairs of finite floats (lo == hi draws a number and returns lo).
      num_reps: replicates (< 2**32).
      on_block: called with the replicates done after each vectorised block (progress).
      on_replicate: passed to :func:`reference_draws` if it must run instead.

    Returns:
      The draws, bit-identical to NumPy's generator (checked on :data:`CHECKED_REPLICATES` replicates; if one
      differs, every replicate is drawn by :func:`reference_draws`, with a RuntimeWarning).

    Example:
      >>> import numpy as np
      >>> got = uniform_draws([7, 2], [(0.0, 1.0), (-0.5, 0.5)], 3)
      >>> rng = np.random.default_rng([7, 2, 2])
      >>> bool(np.all(got[2] == [rng.uniform(0.0, 1.0), rng.uniform(-0.5, 0.5)]))
      True
    """
    if not 0 <= num_reps < 2**32:
        raise ValueError(f"num_reps must be in [0, 2**32), got {num_reps}")
    lo = np.array([a for a, _ in ranges], np.float64)
    span = np.array([b for _, b in ranges], np.float64) - lo  # Generator.uniform's range: high - low, float64
    out = np.empty((num_reps, len(ranges)))
    for start in range(0, num_reps, _BLOCK):
        r = np.arange(start, min(start + _BLOCK, num_reps), dtype=np.uint32)
        u = first_doubles(entropy, r, len(ranges))
        out[start:start + r.size] = lo + span * u  # random_uniform: lower + range * next_double, unfused
        if on_block is not None:
            on_block(start + r.size)
    probe = np.unique(np.linspace(0, num_reps - 1, min(CHECKED_REPLICATES, num_reps)).astype(np.int64))
    if probe.size and not np.array_equal(out[probe], reference_draws(entropy, ranges, probe)):
        warnings.warn("the vectorised draws of numpy.random.default_rng differ from NumPy's own on this build; "
                      "drawing every replicate with default_rng (slow)", RuntimeWarning, stacklevel=2)
        return reference_draws(entropy, ranges, range(num_reps), on_replicate)
    return out
