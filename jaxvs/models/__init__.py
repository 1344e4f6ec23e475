"""Linear models: rational transfer functions, modal models, state space."""

from ._analysis import (
    damping as damping,
    is_stable as is_stable,
    poles as poles,
    static_gain as static_gain,
    zeros as zeros,
)
from ._base import AbstractLinearModel as AbstractLinearModel, map_batch as map_batch
from ._chain import NormalModes as NormalModes, OscillatorChain as OscillatorChain
from ._convert import (
    acceleration_to_position as acceleration_to_position,
    acceleration_to_position_frf as acceleration_to_position_frf,
    position_to_acceleration as position_to_acceleration,
    position_to_acceleration_frf as position_to_acceleration_frf,
    to_modal as to_modal,
    to_rational as to_rational,
)
from ._discretise import (
    DiscreteModalRealisation as DiscreteModalRealisation,
    discretise as discretise,
)
from ._family import GridFamily as GridFamily, SmoothFamily as SmoothFamily
from ._modal import ModalModel as ModalModel
from ._rational import RationalTF as RationalTF
from ._realisation import ModalRealisation as ModalRealisation
from ._response import frequency_response as frequency_response
from ._simulate import simulate as simulate
from ._statespace import StateSpace as StateSpace
