"""The TMF virtual-sensor study (Doerrer et al. 2022): transmissibility identification
routes (PRBS, hammer, FRFs, modal) and position-dependent TMF families."""

from ._tmf import (
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
