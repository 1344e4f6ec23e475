"""The thermal virtual-sensor study (Dementjev et al. 2014): exponential interpolation of
sparse targets, input selection, trainlm training of static and time-delay networks,
virtual-sensor metrics and residual analysis."""

from ._first_order import (
    ThermalFitWarning as ThermalFitWarning,
    fit_first_order as fit_first_order,
    fit_piecewise_first_order as fit_piecewise_first_order,
)
from ._metrics import (
    ExtrapolationWarning as ExtrapolationWarning,
    NoOperatingPointChangeWarning as NoOperatingPointChangeWarning,
    ResidualAnalysis as ResidualAnalysis,
    mapd as mapd,
    r2 as r2,
    residual_analysis as residual_analysis,
    rmse as rmse,
    split_train_test as split_train_test,
    vs_metrics as vs_metrics,
)
from ._resample_sparse import (
    correct_outliers as correct_outliers,
    detect_outliers as detect_outliers,
    resample_sparse as resample_sparse,
)
from ._selection import (
    InputRank as InputRank,
    correlation_matrix as correlation_matrix,
    rank_inputs as rank_inputs,
)
from ._train import (
    STOP_REASONS as STOP_REASONS,
    TrainlmOptions as TrainlmOptions,
    TrainResult as TrainResult,
    fit_regression as fit_regression,
    normalise_network as normalise_network,
    train_adam as train_adam,
    train_lm as train_lm,
)
