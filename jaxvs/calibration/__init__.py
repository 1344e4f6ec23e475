"""Calibration: fitting models to data (frequency-domain rational fits, result codes)."""

from ._calibrate import (
    CalibrationError as CalibrationError,
    CalibrationResult as CalibrationResult,
    calibrate as calibrate,
    free_spec as free_spec,
)
from ._family import (
    MultistartResult as MultistartResult,
    calibrate_family as calibrate_family,
    multistart as multistart,
)
from ._fit_rational import FitReport as FitReport, fit_rational as fit_rational
from ._idim import (
    ForcePrediction as ForcePrediction,
    IDIMResult as IDIMResult,
    idim_ls as idim_ls,
    idim_regressor as idim_regressor,
    predict_force as predict_force,
)
from ._lscf import (
    PoleTrack as PoleTrack,
    StabilisationDiagram as StabilisationDiagram,
    pole_tracks as pole_tracks,
    select_poles as select_poles,
    stabilisation_diagram as stabilisation_diagram,
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
