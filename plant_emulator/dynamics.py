"""The plant's dynamics (paper Eq. 1-9): the shared `sea_hil.dynamics` (the controller's nominal model runs the same
equations), importable from here as the plant's own."""
from sea_hil.dynamics import (
                              State,
                              deflections,
                              end_stop_energy,
                              end_stop_torque,
                              equilibrium_nut,
                              f,
                              initial_state,
                              is_finite,
                              saturate,
)

__all__ = ["State", "deflections", "end_stop_energy", "end_stop_torque", "equilibrium_nut", "f", "initial_state",
           "is_finite", "saturate"]
