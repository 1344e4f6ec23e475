"""The analysis band of a drive record: the one preprocessing of position and force.

A servo axis is analysed in a band below the encoder's and the current loop's noise: the
position and the force go through the same zero-phase Butterworth low-pass (so neither is
delayed against the other), velocity and acceleration are its central differences, the
force of a digital drive is moved half a sample later (a held sample acts over the next
period: Franklin, Powell & Workman, *Digital Control of Dynamic Systems*, §6.3), and the
result is cut away from the filter's end transients and decimated to about four samples
per cut-off period. The diagnosis of a drive, its null records and `jaxvs check` read a
record through [`DriveBand`][].

Runs on the host (NumPy/SciPy): it prepares data once per record, before any compiled
program, and must not compile per record length.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import scipy.signal as ss

__all__ = ["DriveBand", "DriveSignals"]


@dataclasses.dataclass(frozen=True)
class DriveSignals:
    """A drive record in its analysis band.

    - `q`, `u`: the low-passed position [m] and force [N] at every sample.
    - `v`, `a`: velocity [m/s] and acceleration [m/s²], central differences of `q`.
    - `window`: the samples kept (away from the end transients, decimated).
    """

    q: np.ndarray
    u: np.ndarray
    v: np.ndarray
    a: np.ndarray
    window: slice


@dataclasses.dataclass(frozen=True)
class DriveBand:
    """Zero-phase low-pass, derivatives, hold compensation and decimation of a drive record.

    - `fs`: sampling rate [Hz].
    - `cutoff_hz`: cut-off of the zero-phase Butterworth filter, `0 < cutoff_hz < fs/2`.
    - `order`: order of the Butterworth prototype.
    - `decimation`: keep every `decimation`-th sample of the band.
    - `hold`: the force is a digital drive's held command (moved half a sample later).

    [`DriveBand.of`][] fills the defaults from the sampling rate.
    """

    fs: float
    cutoff_hz: float
    order: int = 4
    decimation: int = 1
    hold: bool = True

    @classmethod
    def of(
        cls,
        fs: float,
        cutoff_hz: float | None = None,
        *,
        order: int = 4,
        decimation: int | None = None,
        hold: bool = True,
        who: str = "drive",
    ) -> DriveBand:
        """The band of a record sampled at `fs`: cut-off `min(fs/8, 100 Hz)` unless given
        (a servo axis's rigid-body dynamics lie well below 100 Hz), decimation to about
        four samples per cut-off period unless given."""
        fs = float(fs)
        cutoff = float(cutoff_hz or min(fs / 8.0, 100.0))
        if not 0 < cutoff < fs / 2:
            raise ValueError(f"{who}: cutoff_hz={cutoff} must lie in (0, fs/2 = {fs / 2:g}) Hz.")
        nd = int(decimation or max(1, int(fs / (4.0 * cutoff))))
        return cls(fs, cutoff, int(order), nd, bool(hold))

    @property
    def sos(self) -> np.ndarray:
        return ss.butter(self.order, self.cutoff_hz, fs=self.fs, output="sos")

    @property
    def edge(self) -> int:
        """Samples cut at each end: three periods of the cut-off (the filter's memory)."""
        return int(math.ceil(3 * self.fs / self.cutoff_hz))

    @property
    def min_samples(self) -> int:
        """The shortest record the band can analyse."""
        return 20 * self.decimation + 64

    @property
    def enbw(self) -> float:
        """`∫|H(f)|⁴ df` [Hz]: the share of a white force noise's density the zero-phase
        filter passes (`noise_var = density · enbw`)."""
        w, h = ss.sosfreqz(self.sos, worN=4096, fs=self.fs)
        return float(np.trapezoid(np.abs(h) ** 4, w))

    def held(self, u: np.ndarray) -> np.ndarray:
        """The force acting at `t_k`: the mean of the held samples `k-1` and `k` (when
        `hold`), else `u` itself."""
        u = np.asarray(u, float)
        if not self.hold:
            return u
        return np.concatenate([u[:1], 0.5 * (u[1:] + u[:-1])])

    def lowpass(self, x: np.ndarray) -> np.ndarray:
        """Zero-phase low-pass along the last axis, padded by three cut-off periods (the
        filter's memory: a record starting on a slope shows no start-up transient)."""
        x = np.asarray(x, float)
        pad = int(min(x.shape[-1] - 1, 3 * self.fs / self.cutoff_hz))
        return ss.sosfiltfilt(self.sos, x, padlen=pad, axis=-1)

    def derivatives(self, qf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Velocity and acceleration of a low-passed position: second-order central
        differences (one-sided of second order at the ends)."""
        v = np.gradient(qf, 1.0 / self.fs, edge_order=2, axis=-1)
        return v, np.gradient(v, 1.0 / self.fs, edge_order=2, axis=-1)

    def window(self, n: int) -> slice:
        """The samples kept of a record of `n`: away from the ends, decimated."""
        return slice(self.edge, n - self.edge, self.decimation)

    def apply(self, q: np.ndarray, u: np.ndarray) -> DriveSignals:
        """The record in the band: position and (held) force low-passed, the derivatives,
        the window of samples kept."""
        q = np.asarray(q, float)
        qf = self.lowpass(q)
        v, a = self.derivatives(qf)
        return DriveSignals(qf, self.lowpass(self.held(u)), v, a, self.window(q.size))
