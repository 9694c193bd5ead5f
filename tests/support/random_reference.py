"""The counter-based streams of ``functional/_random.py`` in plain Python integers.

No torch op, no device, no engine: if the library's tensors equal these numbers on the CPU,
they are the same numbers on any device that does int32 wrapping arithmetic (every torch
backend), because nothing else enters the hash.
"""

from __future__ import annotations

import math

M32 = 0xFFFFFFFF
GOLDEN = 0x9E3779B9
MULTIPLIER = 0x45D9F3B


def mix(x: int) -> int:
    x &= M32
    x ^= x >> 16
    x = (x * MULTIPLIER) & M32
    x ^= x >> 16
    x = (x * MULTIPLIER) & M32
    return x ^ (x >> 16)


def salt(seed: int) -> int:
    return mix(mix((seed & M32) ^ GOLDEN) ^ ((seed >> 32) & M32))


def purpose_word(purpose: int) -> int:
    return (purpose * 0x27D4EB2F + 0x165667B1) & M32


def sample_key(seed: int) -> int:
    """``entry_keys(salt, 0)``: the key of a sample's events (int64 counter 0, purpose 0)."""
    return mix(mix(0 ^ salt(seed)) ^ 0 ^ purpose_word(0))


def sub_hash(seed: int, within: int, purpose: int) -> int:
    return mix(sample_key(seed) ^ ((within * 0x61C88647 + purpose_word(purpose)) & M32))


def uniform(seed: int, within: int, purpose: int) -> float:
    """``EventStream.uniform``: 32 random bits in (0, 1)."""
    return (((sub_hash(seed, within, purpose) + 2**31) & M32) + 0.5) * 2.0**-32


def uniform32(seed: int, within: int, purpose: int) -> float:
    """``EventStream.uniform32``: 23 random bits in (0, 1)."""
    return (((sub_hash(seed, within, purpose) >> 9) & 0x7FFFFF) + 0.5) * 2.0**-23


def normal_pair(seed: int, within: int, purpose: int) -> tuple[float, float]:
    """``EventStream.normal_pair`` (Box-Muller on the 23-bit uniforms of purposes 2 p + 1 and
    2 p + 2), in float64: the library computes it in float32, so compare to ~1e-6."""
    radius = math.sqrt(-2.0 * math.log(uniform32(seed, within, 2 * purpose + 1)))
    angle = 2 * math.pi * uniform32(seed, within, 2 * purpose + 2)
    return radius * math.cos(angle), radius * math.sin(angle)


def normal(seed: int, within: int, purpose: int) -> float:
    return normal_pair(seed, within, purpose)[0]


def stream_uniform(seed: int, counter: int, purpose: int) -> float:
    """``_random.uniform(sample_salts(seed), counter (int64), purpose)``."""
    x = mix((counter & M32) ^ salt(seed)) ^ ((counter >> 32) & M32)
    return (((mix(x ^ purpose_word(purpose)) + 2**31) & M32) + 0.5) * 2.0**-32


def entry_key(seed: int, counter: int) -> int:
    """``entry_keys(sample_salts(seed), counter)`` (int64 counter, purpose 0)."""
    x = mix((counter & M32) ^ salt(seed)) ^ ((counter >> 32) & M32)
    return mix(x ^ purpose_word(0))


def key_uniform(key: int, within: int, purpose: int, bits: int = 32) -> float:
    """``sub_uniform(key, within, purpose, bits=bits)`` of an entry key."""
    first = mix(key ^ ((within * 0x61C88647 + purpose_word(purpose)) & M32))
    if bits == 53:
        second = mix(first ^ GOLDEN)
        return ((first >> 6) * 2**27 + (second >> 5)) * 2.0**-53
    return (((first + 2**31) & M32) + 0.5) * 2.0**-32


def _stirling_tail(k: float) -> float:
    if k < 10:
        return math.lgamma(k + 1) - ((k + 0.5) * math.log(k + 1) - (k + 1) + 0.5 * math.log(2 * math.pi))
    square = (k + 1) ** 2
    return (1.0 / 12 - (1.0 / 360 - 1.0 / 1260 / square) / square) / (k + 1)


def binomial_large(key: int, n: int, prob: float, purpose: int) -> int:
    """``_random.binomial_large`` for one entry, one number at a time: inversion of the CDF
    (64 terms) when ``n min(p, 1 - p) < 10``, else BTRS over candidates 0, 1, 2, ... (16 per
    round in the library: the same counters, so the first accepted candidate is the same)."""
    flip = prob > 0.5
    p = 1.0 - prob if flip else prob
    q = 1.0 - p
    r = p / q
    if n * p < 10.0:
        u = key_uniform(key, 0, purpose, 53)
        pmf0 = math.exp(n * math.log1p(-p))
        cdf, k, product = pmf0, 0, 1.0
        while cdf < u and k < 63:  # the library: pmf0 times the running product of the ratios
            product *= max(n - k, 0) / (k + 1) * r
            cdf += pmf0 * product
            k += 1
        k = min(k, n)
    else:
        spq = math.sqrt(n * p * q)
        b = 1.15 + 2.53 * spq
        a = -0.0873 + 0.0248 * b + 0.01 * p
        c = n * p + 0.5
        v_r = 0.92 - 4.2 / b
        alpha = (2.83 + 5.1 / b) * spq
        m = math.floor((n + 1) * p)
        h = _stirling_tail(m) + _stirling_tail(n - m)
        within = 0
        while True:
            us_ = key_uniform(key, within, purpose + 1, 53) - 0.5
            v = key_uniform(key, within, purpose + 2)
            within += 1
            us = 0.5 - abs(us_)
            if us == 0.0:
                continue
            k = math.floor((2 * a / us + b) * us_ + c)
            if k < 0 or k > n:
                continue
            if us >= 0.07 and v <= v_r:
                break
            log_v = math.log(v * alpha / (a / (us * us) + b))
            bound = (
                (m + 0.5) * math.log((m + 1) / (r * (n - m + 1)))
                + (n + 1) * math.log1p((k - m) / (n - k + 1))
                + (k + 0.5) * math.log(r * (n - k + 1) / (k + 1))
                + h - _stirling_tail(k) - _stirling_tail(n - k)
            )
            if log_v <= bound:
                break
    return n - k if flip else k
