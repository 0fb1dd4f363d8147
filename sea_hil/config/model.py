"""Config sections of the physics and the control law: plant, disturbance, trajectory, controller, trigger, sim."""
from __future__ import annotations

from typing import Literal

from pydantic import Field

from sea_hil.config.base import Pair, _Frozen
from sea_hil.config.safety import EndStopConfig


class PlantConfig(_Frozen):
    """Physical parameters of the limb (paper Fig. 1 and Sec. 4) and of the SEAs (Eq. 6)."""
    d_m: tuple[float, float, float, float, float, float, float, float, float, float] = Field(
        description="d1..d10 of Fig. 1 in metres")
    r1_m: float
    r2_m: float
    l1_m: float
    l2_m: float
    m1_kg: float = Field(gt=0)
    m2_kg: float = Field(gt=0)
    i1_kgm2: float = Field(ge=0)
    i2_kgm2: float = Field(ge=0)
    k1_n_per_m: float = Field(gt=0)
    k2_n_per_m: float = Field(gt=0)
    b1_nms: float = Field(ge=0)
    b2_nms: float = Field(ge=0)
    g_m_s2: float = 9.81
    alpha1_rad: float
    alpha2_rad: float
    theta_ref_rad: Pair = (0.0, 0.0)
    initial_theta_rad: Pair = Field((0.05, 0.2831), description="joint angles the driver boots at (rest, holding)")
    nut_damping_per_s: float = Field(48.0, ge=0)
    voltage_limit_v: float = Field(24.0, gt=0)
    include_i2_in_coupling: bool = True
    end_stops: EndStopConfig = EndStopConfig()


class DisturbanceConfig(_Frozen):
    kind: Literal["none", "constant", "sine", "noise"] = "none"
    amplitude_nm: Pair = (0.0, 0.0)
    frequency_hz: float = Field(0.5, ge=0)
    noise_hold_s: float = Field(0.01, gt=0)
    seed: int = 0


class TrajectoryConfig(_Frozen):
    kind: Literal["gait", "csv"] = "gait"
    period_s: float = Field(10.0, gt=0)
    csv_path: str = ""
    lead_in_s: float = Field(0.5, ge=0, description="networked session: quintic from the measured start state onto "
                             "the trajectory before the measured cycles; 0 = start the cycles at once")


class ControllerConfig(_Frozen):
    c: float = Field(gt=0)
    rho: float = Field(ge=0)
    kp1: float = Field(gt=0)
    kp2: float = Field(gt=0)
    boundary_layer: float = Field(0.0, ge=0, description="0 = sign(s) as in the paper; >0 = sat(s/phi)")
    sample_period_s: float = Field(0.01, gt=0)
    inner_rate_hz: float = Field(1000.0, gt=0)
    cross_term_scale: Literal["normalized", "paper", "off"] = "normalized"
    cross_term_bandwidth_rad_s: float = Field(30.0, gt=0, description="omega_c of the normalized Eq. 27 cross term")


class TriggerConfig(_Frozen):
    r: float = Field(gt=0)
    eta: float = Field(gt=0)
    lipschitz_l: float = Field(gt=0)
    max_inter_event_s: float = Field(0.25, gt=0)


class SimConfig(_Frozen):
    substeps: int = Field(2, ge=1)
    cycles: int = Field(1, ge=1)
