"""Family-agnostic calibration: `calibrate`, residuals, parametrisations, covariance,
families and sharding, one Levenberg-Marquardt, the rational and modal fitters and their
linear initialisers (Levy, Sanathanan-Koerner, pLSCF)."""

from ._calibrate import (
    CalibrateOptions as CalibrateOptions,
    CalibrationError as CalibrationError,
    CalibrationResult as CalibrationResult,
    calibrate as calibrate,
    free_spec as free_spec,
)
from ._evidence import (
    EvidenceSelection as EvidenceSelection,
    backward_elimination as backward_elimination,
    log_evidence as log_evidence,
    stability_selection as stability_selection,
)
from ._family import (
    MultistartResult as MultistartResult,
    calibrate_family as calibrate_family,
    multistart as multistart,
)
from ._fit_rational import (
    FitReport as FitReport,
    fit_rational as fit_rational,
)
from ._lm import (
    AbstractDamping as AbstractDamping,
    AbstractLMMonitor as AbstractLMMonitor,
    BatchSchedule as BatchSchedule,
    LevenbergMarquardt as LevenbergMarquardt,
    LMState as LMState,
    MarquardtDamping as MarquardtDamping,
    NielsenDamping as NielsenDamping,
    batched_while as batched_while,
    jacobian_normal_equations as jacobian_normal_equations,
    lm_init as lm_init,
    lm_result as lm_result,
    lm_running as lm_running,
    lm_solve as lm_solve,
    lm_solve_family as lm_solve_family,
    lm_step as lm_step,
)
from ._lscf import (
    PoleTrack as PoleTrack,
    StabilisationCriteria as StabilisationCriteria,
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
from ._results import RESULTS as RESULTS, describe as describe
from ._sharding import (
    SweepResult as SweepResult,
    calibrate_family_sharded as calibrate_family_sharded,
    family_mesh as family_mesh,
    shard_family as shard_family,
    simulate_sharded as simulate_sharded,
    sweep as sweep,
)
