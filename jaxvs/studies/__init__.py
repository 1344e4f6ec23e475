"""The source studies' workflows, built on the generic engines of `jaxvs.calibration`.

- `jaxvs.studies.thermal`: thermal virtual sensor (trainlm, sparse resampling, input
  selection, virtual-sensor metrics);
- `jaxvs.studies.drive`: CNC axis drives (IDIM-LS, closed-loop calibration);
- `jaxvs.studies.machine`: the three-axis machine's 21 geometric errors (volumetric
  calibration, identifiability of test plans, test-plan suggestion);
- `jaxvs.studies.tmf`: TMF virtual sensor (identification routes, position families);
- `jaxvs.studies.benchmarks`: public identification benchmarks as tasks (EMPS first);
- `jaxvs.studies.design`: the virtual-sensor design assistant (`jaxvs.design`).

Every public name of the sub-packages is also available here.
"""

from . import (
    benchmarks as benchmarks,
    design as design,
    drive as drive,
    machine as machine,
    thermal as thermal,
    tmf as tmf,
)
from .design import DesignReport as DesignReport
from .drive import (
    DriveSignals as DriveSignals,
    ForcePrediction as ForcePrediction,
    IDIMResult as IDIMResult,
    calibrate_drive as calibrate_drive,
    drive_residual as drive_residual,
    idim_ls as idim_ls,
    idim_regressor as idim_regressor,
    predict_force as predict_force,
)
from .machine import (
    IdentifiabilityReport as IdentifiabilityReport,
    MachineCalibration as MachineCalibration,
    calibrate_machine as calibrate_machine,
    compensated_error as compensated_error,
    identifiability as identifiability,
    suggest_test as suggest_test,
)
from .thermal import (
    STOP_REASONS as STOP_REASONS,
    ExtrapolationWarning as ExtrapolationWarning,
    InputRank as InputRank,
    NoOperatingPointChangeWarning as NoOperatingPointChangeWarning,
    ResidualAnalysis as ResidualAnalysis,
    ThermalFitWarning as ThermalFitWarning,
    TrainlmOptions as TrainlmOptions,
    TrainResult as TrainResult,
    correct_outliers as correct_outliers,
    correlation_matrix as correlation_matrix,
    detect_outliers as detect_outliers,
    fit_first_order as fit_first_order,
    fit_piecewise_first_order as fit_piecewise_first_order,
    fit_regression as fit_regression,
    mapd as mapd,
    normalise_network as normalise_network,
    r2 as r2,
    rank_inputs as rank_inputs,
    resample_sparse as resample_sparse,
    residual_analysis as residual_analysis,
    rmse as rmse,
    split_train_test as split_train_test,
    train_adam as train_adam,
    train_lm as train_lm,
    vs_metrics as vs_metrics,
)
from .tmf import (
    ExcitationLocationWarning as ExcitationLocationWarning,
    TMFFit as TMFFit,
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
