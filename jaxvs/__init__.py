"""jaxvs: virtual sensors of machine tools and diagnosis of the sim-to-real gap, in JAX.

Enable float64 for calibration in your own program (library code never does it):

    import jax
    jax.config.update("jax_enable_x64", True)
"""

from . import data as data, models as models
from .models import (
    AbstractLinearModel as AbstractLinearModel,
    ModalModel as ModalModel,
    RationalTF as RationalTF,
    StateSpace as StateSpace,
    frequency_response as frequency_response,
)

__version__ = "0.1.0"
