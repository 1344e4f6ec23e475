"""TMF virtual sensor: the encoder-to-tool-centre-point transmissibility applied in real time."""

from ._stable import (
    StableTMF as StableTMF,
    partial_fractions as partial_fractions,
    pole_sections as pole_sections,
    section_poles as section_poles,
    simulate_modal as simulate_modal,
)
from ._virtual_sensor import VirtualSensor as VirtualSensor
