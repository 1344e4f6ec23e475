"""`FRFData`: a measured (or estimated) frequency response with its quality indicators."""

from __future__ import annotations

from collections.abc import Hashable, Mapping
from types import MappingProxyType
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Complex, Float

from .._misc import check_finite, first_not_increasing, is_traced, real_array

# What an FRF relates (Ewins, *Modal Testing*, 2000, ch. 1): response per force as
# displacement (receptance), velocity (mobility) or acceleration (accelerance); a response
# per response is a transmissibility (study 002, eq. 6); "frf" is anything else.
FRF_KINDS = ("frf", "receptance", "mobility", "accelerance", "transmissibility")

# Heuristic: estimated coherences are |Sxy|²/(Sxx·Syy) and exceed 1 by rounding only
# (a few ulp in float64, ~1e-6 in float32); anything further outside [0, 1] is a bug.
_COHERENCE_SLACK = 1e-4


def _freeze_metadata(metadata: Mapping[str, Any] | None) -> tuple[tuple[str, Any], ...]:
    if metadata is None:
        return ()
    if not isinstance(metadata, Mapping):
        raise TypeError(
            f"FRFData: metadata must be a mapping (dict), got {type(metadata).__name__}."
        )
    items = []
    for key, value in metadata.items():
        if not isinstance(key, str):
            raise TypeError(f"FRFData: metadata keys must be strings, got {key!r}.")
        if isinstance(value, list):
            value = tuple(value)
        if not isinstance(value, Hashable) or isinstance(value, (np.ndarray, jax.Array)):
            raise TypeError(
                f"FRFData: metadata[{key!r}] = {type(value).__name__} is not hashable. Metadata "
                "is static (it is part of the jit cache key): give numbers, strings or tuples, "
                "and keep arrays in the data fields."
            )
        items.append((key, value))
    return tuple(items)


class FRFData(eqx.Module):
    """A frequency response on a frequency grid, with its coherence and provenance.

    The container every FRF estimator of `jaxvs.signal` returns and every frequency-domain
    calibration consumes. It is an immutable `eqx.Module` (a pytree), so it passes through
    `jax.jit` / `jax.vmap`; its units, kind and metadata are static.

    **Arguments:**

    - `frequency`: `(freq,)` frequencies [Hz], finite, >= 0 and strictly increasing.
    - `H`: complex response, `(*batch, freq)` for one input and one output, or
      `(*batch, freq, out, in)`; leading `batch` axes hold a family (e.g. one FRF per
      position of another axis). Real input is promoted to complex. Finite.
    - `coherence`: optional ordinary coherence `γ²` in [0, 1], same shape as `H` (real).
    - `n_averages`: optional number of averaged blocks (segments × records) behind the
      estimate; the variance of an H1 estimate scales as `(1 − γ²) / (2 n γ²)` (Bendat &
      Piersol, *Random Data*, 4th ed., 2010, ch. 9).
    - `input_unit`, `output_unit`: units of the excitation and the response, e.g. `"N"` and
      `"m/s^2"` (`H` then has unit `output_unit / input_unit`); `""` when unknown.
    - `kind`: one of `"frf"`, `"receptance"`, `"mobility"`, `"accelerance"`,
      `"transmissibility"`.
    - `metadata`: optional mapping `str -> hashable` (estimator, window, `fs`, ...).
    - `io_shape`: `()` for a single-input single-output `H`, `(out, in)` otherwise. Inferred
      from the shapes; give it only when both readings fit (e.g. `H` of shape
      `(5, 5, 5)` with 5 frequencies).

    **Raises:**

    `ValueError` for mismatched shapes, non-finite values, a frequency grid that is not
    strictly increasing or negative, a coherence outside [0, 1], an unknown `kind`;
    `TypeError` for a complex frequency or coherence and for unhashable metadata. Values
    that are traced under `jax.jit` are checked with `eqx.error_if` instead.

    !!! note
        Under a user's own `jax.vmap` the `frequency` leaf gains the mapped axes too; the
        estimators of `jaxvs.signal` batch over leading axes natively and keep one grid.
    """

    frequency: Float[Array, " freq"]
    H: Complex[Array, "*batch freq"] | Complex[Array, "*batch freq out in"]
    coherence: Float[Array, "*batch freq"] | Float[Array, "*batch freq out in"] | None
    n_averages: int | None = eqx.field(static=True)
    input_unit: str = eqx.field(static=True)
    output_unit: str = eqx.field(static=True)
    kind: str = eqx.field(static=True)
    io_shape: tuple[int, ...] = eqx.field(static=True)
    _metadata: tuple[tuple[str, Any], ...] = eqx.field(static=True)

    def __init__(
        self,
        frequency: ArrayLike,
        H: ArrayLike,
        *,
        coherence: ArrayLike | None = None,
        n_averages: int | None = None,
        input_unit: str = "",
        output_unit: str = "",
        kind: str = "frf",
        metadata: Mapping[str, Any] | None = None,
        io_shape: tuple[int, ...] | None = None,
    ):
        frequency = real_array(
            frequency, "FRFData: frequency must be real [Hz]; got a complex array."
        )
        if frequency.ndim != 1 or frequency.shape[0] < 1:
            raise ValueError(
                f"FRFData: frequency must be a non-empty 1-D grid (freq,) in Hz; got shape "
                f"{frequency.shape}. One grid serves the whole family: keep family axes on H."
            )
        n_freq = frequency.shape[0]

        H = jnp.asarray(H)
        if not jnp.iscomplexobj(H):
            if not jnp.issubdtype(H.dtype, jnp.floating):
                H = H.astype(jnp.result_type(float))
            H = H.astype(jnp.result_type(H.dtype, jnp.complex64))
        siso_fits = H.ndim >= 1 and H.shape[-1] == n_freq
        mimo_fits = H.ndim >= 3 and H.shape[-3] == n_freq
        if io_shape is None:
            if siso_fits and mimo_fits:
                raise ValueError(
                    f"FRFData: H of shape {H.shape} reads both as (*batch, freq) and as "
                    f"(*batch, freq, out, in) with {n_freq} frequencies; pass io_shape=() or "
                    "io_shape=(out, in) to say which."
                )
            if not (siso_fits or mimo_fits):
                raise ValueError(
                    f"FRFData: H of shape {H.shape} does not match {n_freq} frequencies; "
                    "expected (*batch, freq) or (*batch, freq, out, in)."
                )
            io_shape = () if siso_fits else tuple(H.shape[-2:])
        else:
            io_shape = tuple(int(k) for k in io_shape)
            ok = (io_shape == () and siso_fits) or (
                len(io_shape) == 2 and mimo_fits and tuple(H.shape[-2:]) == io_shape
            )
            if not ok:
                raise ValueError(
                    f"FRFData: H of shape {H.shape} does not fit io_shape={io_shape} with "
                    f"{n_freq} frequencies; expected (*batch, freq) for io_shape=() or "
                    "(*batch, freq, out, in) for io_shape=(out, in)."
                )

        if coherence is not None:
            coherence = jnp.asarray(coherence)
            if jnp.iscomplexobj(coherence):
                raise TypeError(
                    "FRFData: coherence must be real (the ordinary coherence γ² in [0, 1])."
                )
            if not jnp.issubdtype(coherence.dtype, jnp.floating):
                coherence = coherence.astype(jnp.result_type(float))
            if coherence.shape != H.shape:
                raise ValueError(
                    f"FRFData: coherence has shape {coherence.shape} but H has {H.shape}; "
                    "give one coherence value per FRF value."
                )

        if n_averages is not None:
            if isinstance(n_averages, bool) or not isinstance(n_averages, (int, np.integer)):
                raise TypeError(
                    f"FRFData: n_averages must be a Python int, got {type(n_averages).__name__}."
                )
            n_averages = int(n_averages)
            if n_averages < 1:
                raise ValueError(f"FRFData: n_averages must be >= 1, got {n_averages}.")
        for name, unit in (("input_unit", input_unit), ("output_unit", output_unit)):
            if not isinstance(unit, str):
                raise TypeError(f"FRFData: {name} must be a string such as 'N', got {unit!r}.")
        if kind not in FRF_KINDS:
            raise ValueError(f"FRFData: unknown kind {kind!r}; choose one of {FRF_KINDS}.")

        frequency = _check_grid(frequency)
        H = _check_finite(H, "H")
        if coherence is not None:
            coherence = _check_finite(coherence, "coherence")
            coherence = _check_coherence_range(coherence)

        self.frequency = frequency
        self.H = H
        self.coherence = coherence
        self.n_averages = n_averages
        self.input_unit = input_unit
        self.output_unit = output_unit
        self.kind = kind
        self.io_shape = io_shape
        self._metadata = _freeze_metadata(metadata)

    # -- shape information -------------------------------------------------------------

    @property
    def n_freq(self) -> int:
        """Number of frequencies (static)."""
        return self.frequency.shape[-1]

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Leading family axes of `H` (static)."""
        core = 1 + len(self.io_shape)
        return tuple(self.H.shape[: self.H.ndim - core])

    @property
    def is_siso(self) -> bool:
        return self.io_shape == ()

    @property
    def n_outputs(self) -> int:
        return self.io_shape[0] if self.io_shape else 1

    @property
    def n_inputs(self) -> int:
        return self.io_shape[1] if self.io_shape else 1

    @property
    def omega(self) -> Float[Array, " freq"]:
        """Angular frequencies `2π f` [rad/s], the grid `jaxvs.frequency_response` takes."""
        return 2 * jnp.pi * self.frequency

    @property
    def metadata(self) -> Mapping[str, Any]:
        """Read-only view of the metadata."""
        return MappingProxyType(dict(self._metadata))

    # -- host-side helpers -------------------------------------------------------------

    def select(self, f_min: float | None = None, f_max: float | None = None) -> FRFData:
        """The FRF restricted to `f_min <= f <= f_max` [Hz] (either bound may be `None`).

        Runs on the host (the number of kept frequencies decides the output shape), so call
        it outside `jax.jit`.

        **Returns:**

        A new `FRFData` with the same units, kind, averages and metadata.

        **Raises:**

        `ValueError` when `f_min > f_max` or when no frequency lies in the band.
        """
        if is_traced(self.frequency) or self.frequency.ndim != 1:
            raise TypeError(
                "FRFData.select: needs one concrete frequency grid; call it outside "
                "jax.jit/jax.vmap."
            )
        f = np.asarray(self.frequency)
        lo = -np.inf if f_min is None else float(f_min)
        hi = np.inf if f_max is None else float(f_max)
        if lo > hi:
            raise ValueError(f"FRFData.select: f_min = {lo} Hz is above f_max = {hi} Hz.")
        keep = np.flatnonzero((f >= lo) & (f <= hi))
        if keep.size == 0:
            raise ValueError(
                f"FRFData.select: no frequency in [{lo}, {hi}] Hz; the data covers "
                f"{f[0]:g} to {f[-1]:g} Hz."
            )
        axis = -1 - len(self.io_shape)
        take = lambda a: None if a is None else jnp.take(a, jnp.asarray(keep), axis=axis)
        return FRFData(
            self.frequency[keep],
            take(self.H),
            coherence=take(self.coherence),
            n_averages=self.n_averages,
            input_unit=self.input_unit,
            output_unit=self.output_unit,
            kind=self.kind,
            metadata=dict(self._metadata),
            io_shape=self.io_shape,
        )

    def __repr__(self) -> str:
        io = "SISO" if self.is_siso else f"{self.n_outputs} out x {self.n_inputs} in"
        batch = f", family {self.batch_shape}" if self.batch_shape else ""
        unit_in = self.input_unit or "?"
        unit_out = self.output_unit or "?"
        parts = [f"kind={self.kind!r}", f"{io}{batch}", f"{unit_in!r} -> {unit_out!r}"]
        if is_traced(self.frequency) or self.frequency.ndim != 1:
            parts.append(f"{self.n_freq} frequencies")
        else:
            f = np.asarray(self.frequency)
            step = f"{f[1] - f[0]:.4g} Hz" if f.size > 1 else "-"
            parts.append(f"{f.size} frequencies {f[0]:.4g}..{f[-1]:.4g} Hz (df={step})")
        if self.coherence is not None:
            if is_traced(self.coherence):
                parts.append("coherence")
            else:
                c = np.asarray(self.coherence)
                parts.append(f"coherence {c.min():.3f}..{c.max():.3f} (median {np.median(c):.3f})")
        if self.n_averages is not None:
            parts.append(f"n_averages={self.n_averages}")
        if self._metadata:
            parts.append("metadata=" + ", ".join(f"{k}={v!r}" for k, v in self._metadata))
        return "FRFData(" + ", ".join(parts) + ")"


def _check_grid(frequency: Array) -> Array:
    if is_traced(frequency):
        bad = ~jnp.all(jnp.isfinite(frequency)) | jnp.any(frequency < 0)
        if frequency.shape[0] > 1:
            bad = bad | jnp.any(jnp.diff(frequency) <= 0)
        return eqx.error_if(
            frequency,
            bad,
            "FRFData: frequency must be finite, >= 0 Hz and strictly increasing.",
        )
    f = np.asarray(frequency)
    if not np.all(np.isfinite(f)):
        raise ValueError(
            "FRFData: frequency has a non-finite value at index "
            f"{int(np.argmax(~np.isfinite(f)))}; remove that point (and the same point of H) "
            "before building the FRFData."
        )
    if np.any(f < 0):
        raise ValueError(
            f"FRFData: frequency {f[np.argmax(f < 0)]} Hz is negative; store the one-sided "
            "response of the real system (f >= 0)."
        )
    k = first_not_increasing(f)
    if k is not None:
        raise ValueError(
            f"FRFData: frequency is not strictly increasing: f[{k}] = {float(f[k])!r} Hz <= "
            f"f[{k - 1}] = {float(f[k - 1])!r} Hz. Sort the grid (and H with it) and drop "
            "duplicates."
        )
    return frequency


def _check_finite(x: Array, name: str) -> Array:
    fix = (
        "Remove those frequencies (e.g. a DC bin where the input has no power, which makes an "
        "estimate divide by a zero spectrum) before building the FRFData."
    )
    return check_finite(x, f"FRFData: {name}", fix)


def _check_coherence_range(c: Array) -> Array:
    message = "FRFData: coherence must lie in [0, 1]."
    if is_traced(c):
        return eqx.error_if(c, jnp.any((c < 0) | (c > 1 + _COHERENCE_SLACK)), message)
    values = np.asarray(c)
    if values.size and (values.min() < 0 or values.max() > 1 + _COHERENCE_SLACK):
        raise ValueError(
            f"{message} Got values in [{values.min():.6g}, {values.max():.6g}]; give the "
            "ordinary (squared) coherence |Sxy|²/(Sxx·Syy), not its square root or a dB value."
        )
    return c
