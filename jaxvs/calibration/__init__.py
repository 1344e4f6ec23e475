"""Calibration: fitting models to data (frequency-domain rational fits, result codes)."""

from ._calibrate import (
    CalibrationError as CalibrationError,
    CalibrationResult as CalibrationResult,
    calibrate as calibrate,
    free_spec as free_spec,
)
from ._drive_calibration import (
    calibrate_drive as calibrate_drive,
    drive_residual as drive_residual,
)
from ._family import (
    MultistartResult as MultistartResult,
    calibrate_family as calibrate_family,
    multistart as multistart,
)
from ._first_order import (
    ThermalFitWarning as ThermalFitWarning,
    fit_first_order as fit_first_order,
    fit_piecewise_first_order as fit_piecewise_first_order,
)
from ._fit_rational import FitReport as FitReport, fit_rational as fit_rational
from ._idim import (
    ForcePrediction as ForcePrediction,
    IDIMResult as IDIMResult,
    idim_ls as idim_ls,
    idim_regressor as idim_regressor,
    predict_force as predict_force,
)
from ._lm import (
    LMState as LMState,
    batched_while as batched_while,
    lm_init as lm_init,
    lm_result as lm_result,
    lm_running as lm_running,
    lm_step as lm_step,
)
from ._lscf import (
    PoleTrack as PoleTrack,
    StabilisationDiagram as StabilisationDiagram,
    pole_tracks as pole_tracks,
    select_poles as select_poles,
    stabilisation_diagram as stabilisation_diagram,
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
from ._modal_fit import (
    ModalFit as ModalFit,
    ModalTMF as ModalTMF,
    lsfd as lsfd,
    modal_fit as modal_fit,
    tmf_from_modal as tmf_from_modal,
)
from ._parametrise import (
    AbstractParameter as AbstractParameter,
    Bounded as Bounded,
    Fixed as Fixed,
    Positive as Positive,
    StableDenominator as StableDenominator,
    bounded as bounded,
    fixed as fixed,
    positive as positive,
    stable as stable,
    stable_denominator as stable_denominator,
    unwrap as unwrap,
)
from ._resample_sparse import (
    correct_outliers as correct_outliers,
    detect_outliers as detect_outliers,
    resample_sparse as resample_sparse,
)
from ._residuals import (
    AbstractResidual as AbstractResidual,
    EquationError as EquationError,
    ExcitationWarning as ExcitationWarning,
    FrequencyError as FrequencyError,
    Joint as Joint,
    PredictionError as PredictionError,
    SimulationError as SimulationError,
)
from ._results import RESULTS as RESULTS
from ._selection import (
    InputRank as InputRank,
    correlation_matrix as correlation_matrix,
    rank_inputs as rank_inputs,
)
from ._sharding import (
    SweepResult as SweepResult,
    calibrate_family_sharded as calibrate_family_sharded,
    family_mesh as family_mesh,
    shard_family as shard_family,
    simulate_sharded as simulate_sharded,
    sweep as sweep,
)
from ._tmf import (
    ExcitationLocationWarning as ExcitationLocationWarning,
    TMFIdentification as TMFIdentification,
    check_excitation_location as check_excitation_location,
    family_error as family_error,
    tmf_family as tmf_family,
    tmf_from_accelerations as tmf_from_accelerations,
    tmf_from_frfs as tmf_from_frfs,
    tmf_from_hammer as tmf_from_hammer,
    tmf_from_impacts as tmf_from_impacts,
    tmf_from_time_domain as tmf_from_time_domain,
    with_static_gain as with_static_gain,
)
from ._train import (
    STOP_REASONS as STOP_REASONS,
    TrainResult as TrainResult,
    fit_regression as fit_regression,
    normalise_network as normalise_network,
    train_adam as train_adam,
    train_lm as train_lm,
)
