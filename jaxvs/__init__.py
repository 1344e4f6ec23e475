"""jaxvs: virtual sensors of machine tools and diagnosis of the sim-to-real gap, in JAX.

Enable float64 for calibration in your own program (library code never does it):

    import jax
    jax.config.update("jax_enable_x64", True)
"""

from . import calibration as calibration, data as data, models as models, signal as signal
from .calibration import (
    CalibrationResult as CalibrationResult,
    FitReport as FitReport,
    ModalFit as ModalFit,
    StabilisationDiagram as StabilisationDiagram,
    calibrate as calibrate,
    calibrate_family as calibrate_family,
    fit_rational as fit_rational,
    idim_ls as idim_ls,
    modal_fit as modal_fit,
    multistart as multistart,
    stabilisation_diagram as stabilisation_diagram,
    tmf_from_modal as tmf_from_modal,
)
from .models import (
    AbstractLinearModel as AbstractLinearModel,
    GridFamily as GridFamily,
    ModalModel as ModalModel,
    NormalModes as NormalModes,
    OscillatorChain as OscillatorChain,
    RationalTF as RationalTF,
    SmoothFamily as SmoothFamily,
    StateSpace as StateSpace,
    acceleration_to_position as acceleration_to_position,
    acceleration_to_position_frf as acceleration_to_position_frf,
    damping as damping,
    discretise as discretise,
    frequency_response as frequency_response,
    is_stable as is_stable,
    poles as poles,
    position_to_acceleration as position_to_acceleration,
    position_to_acceleration_frf as position_to_acceleration_frf,
    simulate as simulate,
    static_gain as static_gain,
    to_modal as to_modal,
    to_rational as to_rational,
    zeros as zeros,
)

__version__ = "0.1.0"
