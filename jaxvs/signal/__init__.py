"""Signal processing: Welch spectra, FRF and transmissibility estimation, coherence, windows,
filtering, resampling, the moving-block bootstrap of autocorrelated series, the best linear
approximation of a system under periodic excitation, the analysis band of a drive record."""

from ._basis import (
    bspline_basis as bspline_basis,
    difference_penalty as difference_penalty,
    quantile_knots as quantile_knots,
    rbf_basis as rbf_basis,
)
from ._bla import (
    BLA as BLA,
    best_linear_approximation as best_linear_approximation,
    find_period as find_period,
    period_noise as period_noise,
    settled_periods as settled_periods,
)
from ._bootstrap import (
    block_bootstrap_indices as block_bootstrap_indices,
    block_bootstrap_means as block_bootstrap_means,
    block_length as block_length,
    integrated_time as integrated_time,
)
from ._cwt import (
    CWTDamping as CWTDamping,
    cwt_damping as cwt_damping,
    cwt_morlet as cwt_morlet,
    cwt_ridge as cwt_ridge,
    morlet_scales as morlet_scales,
)
from ._differentiate import differentiate as differentiate
from ._drive_band import DriveBand as DriveBand, DriveSignals as DriveSignals
from ._filter import decimate as decimate, filtfilt_lowpass as filtfilt_lowpass
from ._resample import resample as resample
from ._spectral import (
    Welch as Welch,
    coherence as coherence,
    csd as csd,
    frf_h1 as frf_h1,
    frf_h2 as frf_h2,
    frf_hv as frf_hv,
    psd as psd,
    transmissibility as transmissibility,
)
from ._windows import (
    WINDOW_NAMES as WINDOW_NAMES,
    boxcar as boxcar,
    exponential_window as exponential_window,
    exponential_window_correction as exponential_window_correction,
    flattop as flattop,
    force_window as force_window,
    get_window as get_window,
    hamming as hamming,
    hann as hann,
    impact_windows as impact_windows,
)
