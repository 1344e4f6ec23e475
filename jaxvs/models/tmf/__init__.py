"""TMF virtual sensor: the encoder-to-tool-centre-point transmissibility applied in real time."""

from ._virtual_sensor import VirtualSensor as VirtualSensor
