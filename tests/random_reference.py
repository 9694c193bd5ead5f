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
