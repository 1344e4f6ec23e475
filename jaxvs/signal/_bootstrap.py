"""The moving-block bootstrap of an autocorrelated series (Künsch 1989, Ann. Statist.
17(3)): resamples made of contiguous blocks whose length follows the series' correlation
time, so the dependence inside a block survives the resampling.

Residuals of a calibrated model or of a virtual sensor are autocorrelated (a missing
effect leaves structure in them by definition); intervals from independent resampling
would be far too narrow. Host-side NumPy: it runs once per comparison on vectors of
residuals.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "block_bootstrap_indices",
    "block_bootstrap_means",
    "block_length",
    "integrated_time",
]


def integrated_time(x: np.ndarray) -> float | None:
    """The integrated autocorrelation time `τ = 1 + 2 Σ ρ_k` of a series [samples],
    summed up to the first non-positive autocorrelation (Geyer's initial positive
    sequence); `None` for fewer than 4 samples or a constant series."""
    e = np.asarray(x, dtype=float)
    e = e - e.mean()
    n = e.size
    if n < 4 or not np.any(e):
        return None
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    f = np.fft.rfft(e, nfft)
    acf = np.fft.irfft(f * np.conj(f), nfft)[:n]
    acf = acf / acf[0]
    nonpos = np.nonzero(acf[1:] <= 0.0)[0]
    k = int(nonpos[0]) + 1 if nonpos.size else n
    return 1.0 + 2.0 * float(np.sum(acf[1:k]))


def block_length(x: np.ndarray, *, minimum: int = 8, maximum: int | None = None) -> int:
    """Block length [samples] for a moving-block bootstrap of the series `x`.

    The integrated autocorrelation time `τ` ([`integrated_time`][]) sets the block:
    `L = max(minimum, ⌈2τ⌉, ⌈N^{1/3}⌉)` (the `N^{1/3}` rate of Hall, Horowitz & Jing
    1995), capped at `maximum` (default `N/10`, so that at least ten blocks exist).
    Blocks several correlation times long keep the dependence inside a block.
    """
    n = np.size(x)
    tau = integrated_time(x)
    if tau is None:
        return max(1, min(minimum, n))
    cap = max(1, n // 10) if maximum is None else maximum
    return int(min(cap, max(minimum, math.ceil(2.0 * tau), math.ceil(n ** (1.0 / 3.0)))))


def _starts(n: int, length: int, n_boot: int, rng: np.random.Generator):
    length = max(1, min(int(length), n))
    n_blocks = -(-n // length)
    return length, rng.integers(0, n, size=(n_boot, n_blocks))


def block_bootstrap_indices(
    n: int, length: int, n_boot: int, rng: np.random.Generator
) -> np.ndarray:
    """Indices of `n_boot` moving-block bootstrap resamples of a series of `n` samples.

    Each resample concatenates `⌈n/length⌉` blocks of `length` consecutive samples with
    uniformly drawn starts (circular, so every sample is equally likely), cut to `n`.
    Index several series with the same array for a paired bootstrap.

    **Returns:** an int array `(n_boot, n)`.
    """
    length, starts = _starts(n, length, n_boot, rng)
    idx = (starts[:, :, None] + np.arange(length)[None, None, :]) % n
    return idx.reshape(n_boot, -1)[:, :n]


def block_bootstrap_means(
    x: np.ndarray, length: int, n_boot: int, rng: np.random.Generator
) -> np.ndarray:
    """Means of `x` over `n_boot` moving-block bootstrap resamples of its last axis.

    The resamples are those of [`block_bootstrap_indices`][] for the same `rng` state
    (`x[..., idx].mean(-1)`), computed from cumulative sums in `O(n + n_boot·n/length)`
    instead of `O(n_boot·n)`; the rows of a 2-D `x` (e.g. squared errors of several
    designs on the same samples) share the blocks, so their replicates are paired.

    **Returns:** `(*x.shape[:-1], n_boot)` replicate means.
    """
    x = np.asarray(x, dtype=float)
    n = x.shape[-1]
    length, starts = _starts(n, length, n_boot, rng)
    last = n - (starts.shape[1] - 1) * length  # samples taken from the last block
    ext = np.concatenate([x, x[..., : length - 1]], axis=-1)
    cs = np.concatenate([np.zeros(x.shape[:-1] + (1,)), np.cumsum(ext, axis=-1)], axis=-1)
    full = cs[..., length : length + n] - cs[..., :n]  # block of `length` at each start
    part = cs[..., last : last + n] - cs[..., :n]
    total = full[..., starts[:, :-1]].sum(axis=-1) + part[..., starts[:, -1]]
    return total / n
