"""jaxvs: virtual sensors of machine tools and diagnosis of the sim-to-real gap, in JAX.

Enable float64 for calibration in your own program (library code never does it):

    import jax
    jax.config.update("jax_enable_x64", True)
"""

# `_interrupt` comes first: the `jaxvs` command handles Ctrl-C from its first instant, before
# JAX is imported (importing it does nothing else, and nothing when jaxvs is a library).
from . import (
    _interrupt,  # noqa: F401
    calibration as calibration,
    data as data,
    diagnosis as diagnosis,
    models as models,
    signal as signal,
    studies as studies,
)
from ._cache import enable_compilation_cache as enable_compilation_cache
from ._io import (
    FORMAT_VERSION as FORMAT_VERSION,
    IncompatibleFileError as IncompatibleFileError,
    load_header as load_header,
    load_model as load_model,
    load_results_csv as load_results_csv,
    save_model as save_model,
    save_results_csv as save_results_csv,
)
from ._progress import Interrupted as Interrupted, Progress as Progress, log_to as log_to
from ._version import __version__ as __version__
from .calibration import (
    CalibrationResult as CalibrationResult,
    FitReport as FitReport,
    ModalFit as ModalFit,
    StabilisationCriteria as StabilisationCriteria,
    StabilisationDiagram as StabilisationDiagram,
    SweepResult as SweepResult,
    calibrate as calibrate,
    calibrate_family as calibrate_family,
    calibrate_family_sharded as calibrate_family_sharded,
    family_mesh as family_mesh,
    fit_rational as fit_rational,
    modal_fit as modal_fit,
    multistart as multistart,
    shard_family as shard_family,
    simulate_sharded as simulate_sharded,
    stabilisation_diagram as stabilisation_diagram,
    sweep as sweep,
    tmf_from_modal as tmf_from_modal,
)
from .diagnosis import (
    CheckReport as CheckReport,
    DiagnosisReport as DiagnosisReport,
    check as check,
    diagnose as diagnose,
)
from .models import (
    AbstractLinearModel as AbstractLinearModel,
    FirstOrder as FirstOrder,
    GridFamily as GridFamily,
    ModalModel as ModalModel,
    NormalModes as NormalModes,
    OscillatorChain as OscillatorChain,
    RationalTF as RationalTF,
    SmoothFamily as SmoothFamily,
    StateSpace as StateSpace,
    VirtualSensor as VirtualSensor,
    acceleration_to_position as acceleration_to_position,
    acceleration_to_position_frf as acceleration_to_position_frf,
    damping as damping,
    discretise as discretise,
    frequency_response as frequency_response,
    from_control as from_control,
    from_scipy as from_scipy,
    is_stable as is_stable,
    poles as poles,
    position_to_acceleration as position_to_acceleration,
    position_to_acceleration_frf as position_to_acceleration_frf,
    simulate as simulate,
    simulate_metrics as simulate_metrics,
    static_gain as static_gain,
    to_control as to_control,
    to_modal as to_modal,
    to_rational as to_rational,
    to_scipy as to_scipy,
    zeros as zeros,
)
from .studies import fit_first_order as fit_first_order, idim_ls as idim_ls
from .studies.design import DesignReport as DesignReport, design as design
