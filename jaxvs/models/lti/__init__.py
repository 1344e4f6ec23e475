"""Linear time-invariant models: rational transfer functions, modal models, state space,
the modal realisation, oscillator chains, normal modes, position families, and the
linear-model queries (poles, zeros, frequency response, conversions, scipy/control interop)."""

from ._analysis import (
    damping as damping,
    is_stable as is_stable,
    poles as poles,
    static_gain as static_gain,
    zeros as zeros,
)
from ._chain import (
    NormalModes as NormalModes,
    OscillatorChain as OscillatorChain,
)
from ._convert import (
    acceleration_to_position as acceleration_to_position,
    acceleration_to_position_frf as acceleration_to_position_frf,
    position_to_acceleration as position_to_acceleration,
    position_to_acceleration_frf as position_to_acceleration_frf,
    to_modal as to_modal,
    to_rational as to_rational,
)
from ._family import (
    GridFamily as GridFamily,
    SmoothFamily as SmoothFamily,
)
from ._interop import (
    from_control as from_control,
    from_scipy as from_scipy,
    to_control as to_control,
    to_scipy as to_scipy,
)
from ._modal import ModalModel as ModalModel
from ._modes import (
    DampedModes as DampedModes,
    damped_modes as damped_modes,
    normal_modes as normal_modes,
)
from ._rational import RationalTF as RationalTF
from ._response import frequency_response as frequency_response
from ._statespace import StateSpace as StateSpace
