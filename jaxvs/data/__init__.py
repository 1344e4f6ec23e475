"""Data layer: validated experiment records, file loaders and writers, time-respecting
calibration/validation splits, and excitation signals."""

from ._excitation import (
    PRBS_ORDERS as PRBS_ORDERS,
    Motion as Motion,
    bang_bang as bang_bang,
    prbs as prbs,
    prbs_taps as prbs_taps,
    swept_sine as swept_sine,
    trapezoid as trapezoid,
    white_noise as white_noise,
)
from ._frf import FRF_KINDS as FRF_KINDS, FRFData as FRFData
from ._loaders import (
    FRF_SUFFIXES as FRF_SUFFIXES,
    SUPPORTED_SUFFIXES as SUPPORTED_SUFFIXES,
    load as load,
    load_csv as load_csv,
    load_emps as load_emps,
    load_frf as load_frf,
    load_hdf5 as load_hdf5,
    load_mat as load_mat,
    load_npz as load_npz,
    save_csv as save_csv,
    save_hdf5 as save_hdf5,
    save_mat as save_mat,
    save_npz as save_npz,
)
from ._machine_tests import (
    BallbarData as BallbarData,
    LaserRuns as LaserRuns,
    load_ballbar_csv as load_ballbar_csv,
    load_laser_csv as load_laser_csv,
)
from ._mapping import (
    load_renamed as load_renamed,
    rename_signals as rename_signals,
    require_signals as require_signals,
)
from ._quality import check_validation as check_validation, signal_quality as signal_quality
from ._record import (
    DEFAULT_TIME_RTOL as DEFAULT_TIME_RTOL,
    Record as Record,
    si_record as si_record,
)
from ._sinumerik import (
    SINUMERIK_ALPHABET as SINUMERIK_ALPHABET,
    decode_sinumerik_base85 as decode_sinumerik_base85,
    load_sinumerik as load_sinumerik,
    load_sinumerik_frf as load_sinumerik_frf,
)
from ._splits import (
    Split as Split,
    split_blocks as split_blocks,
    split_experiments as split_experiments,
)
from ._testbench import (
    is_twincat_scope as is_twincat_scope,
    load_mdf as load_mdf,
    load_tdms as load_tdms,
    load_twincat_scope as load_twincat_scope,
)
from ._uff import (
    load_uff_frf as load_uff_frf,
    load_uff_modes as load_uff_modes,
    load_uff_record as load_uff_record,
    save_uff as save_uff,
    uff_datasets as uff_datasets,
)
from ._units import (
    ORIGINAL_UNITS_KEY as ORIGINAL_UNITS_KEY,
    convert_units as convert_units,
    parse_header as parse_header,
    parse_unit as parse_unit,
    si_unit as si_unit,
    to_si as to_si,
)
