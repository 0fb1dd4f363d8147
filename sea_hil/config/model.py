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


DisturbanceKind = Literal["none", "constant", "sine", "noise"]


class JointDisturbanceConfig(_Frozen):
    """One joint's disturbance torque ([disturbance.hip] / [disturbance.knee]); bounded by |amplitude_nm|."""
    kind: DisturbanceKind = "none"
    amplitude_nm: float = 0.0
    frequency_hz: float = Field(0.5, ge=0, description="sine only")
    noise_hold_s: float = Field(0.01, gt=0, description="noise only: each uniform draw is held this long")


class DisturbanceConfig(_Frozen):
    """Disturbance torques d1, d2 of Eq. 3. The flat keys give both joints one kind (the original form); a
    [disturbance.hip] or [disturbance.knee] table replaces that joint's part (per-joint kinds, `--disturbance`)."""
    kind: DisturbanceKind = "none"
    amplitude_nm: Pair = (0.0, 0.0)
    frequency_hz: float = Field(0.5, ge=0)
    noise_hold_s: float = Field(0.01, gt=0)
    seed: int = 0
    hip: JointDisturbanceConfig | None = None
    knee: JointDisturbanceConfig | None = None

    def per_joint(self) -> tuple[JointDisturbanceConfig, JointDisturbanceConfig]:
        """(hip, knee): the joint tables where given, else that joint's part of the flat keys."""
        flat = [JointDisturbanceConfig(kind=self.kind, amplitude_nm=a, frequency_hz=self.frequency_hz,
                                       noise_hold_s=self.noise_hold_s) for a in self.amplitude_nm]
        return (self.hip or flat[0], self.knee or flat[1])

    def is_zero(self) -> bool:
        """True when every joint's torque is identically zero."""
        return all(j.kind == "none" or j.amplitude_nm == 0.0 for j in self.per_joint())


class TrajectoryConfig(_Frozen):
    kind: Literal["gait", "csv"] = "gait"
    period_s: float = Field(10.0, gt=0)
    csv_path: str = ""
    lead_in_s: float = Field(0.5, ge=0, description="networked session: quintic from the measured start state onto "
                             "the trajectory before the measured cycles; 0 = start the cycles at once")
    lead_in_max_velocity_rad_s: float = Field(1.0, gt=0, description="the lead-in is stretched (from lead_in_s) so that "
                                              "its rest-to-rest part peaks at this: a (re)start far from the "
                                              "trajectory stays inside the drive's velocity limit")


class NominalModelConfig(_Frozen):
    """[controller.model]: the controller's nominal model where it differs from the plant (unset = `[plant]`'s
    value). Used by the outer SMC (Eq. 13), the inner backstepping loop (Eq. 24-31) and the disturbance observer;
    the plant emulator always integrates `[plant]`. `--mismatch` fills it (sea_hil/commands/common.py)."""
    d_m: tuple[float, float, float, float, float, float, float, float, float, float] | None = None
    r1_m: float | None = None
    r2_m: float | None = None
    l1_m: float | None = None
    l2_m: float | None = None
    m1_kg: float | None = Field(None, gt=0)
    m2_kg: float | None = Field(None, gt=0)
    i1_kgm2: float | None = Field(None, ge=0)
    i2_kgm2: float | None = Field(None, ge=0)
    k1_n_per_m: float | None = Field(None, gt=0)
    k2_n_per_m: float | None = Field(None, gt=0)
    b1_nms: float | None = Field(None, ge=0)
    b2_nms: float | None = Field(None, ge=0)
    g_m_s2: float | None = None
    alpha1_rad: float | None = None
    alpha2_rad: float | None = None
    nut_damping_per_s: float | None = Field(None, ge=0)
    include_i2_in_coupling: bool | None = None

    def resolve(self, plant: PlantConfig) -> PlantConfig:
        """The nominal model as a PlantConfig: `plant` with every field set here replaced."""
        given = {k: v for k, v in self.model_dump().items() if v is not None}
        return plant.model_copy(update=given) if given else plant


class ControllerConfig(_Frozen):
    c: float = Field(gt=0)
    rho: float = Field(ge=0)
    kp1: float = Field(gt=0)
    kp2: float = Field(gt=0)
    boundary_layer: float = Field(0.0, ge=0, description="0 = sign(s) as in the paper; >0 = sat(s/phi)")
    sample_period_s: float = Field(0.01, gt=0, description="outer loop: the edge publishes the state and the "
                                   "controller samples it every sample_period_s (inner loop: can.feedback_rate_hz)")
    cross_term_scale: Literal["normalized", "paper", "off"] = "normalized"
    cross_term_bandwidth_rad_s: float = Field(30.0, gt=0, description="omega_c of the normalized Eq. 27 cross term")
    disturbance_compensation: Literal["full", "inner", "off"] = Field(
        "full", description="edge disturbance observer: 'full' = in the inner loop's F_R (Eq. 28) and as an "
        "extra deflection on v_x with its rate in Eq. 27; 'inner' = F_R only; 'off' = the paper's Eq. 24-31 "
        "(docs/deviations.md 10)")
    observer_bandwidth_rad_s: float = Field(400.0, gt=0, description="triple pole of the momentum disturbance "
                                            "observer (third order: the torque and its rate)")
    compensation: Literal["none", "predict"] = Field(
        "predict", description="link-delay compensation: 'predict' (default) = v_x for the state predicted at the "
        "instant the setpoint acts (issue 16, docs/session.md); 'none' = the paper's (v_x for the received state)")
    model: NominalModelConfig = NominalModelConfig()


class TriggerConfig(_Frozen):
    r: float = Field(gt=0)
    eta: float = Field(gt=0)
    lipschitz_l: float = Field(gt=0)
    max_inter_event_s: float = Field(0.25, gt=0)
    placement: Literal["controller", "edge"] = Field(
        "edge", description="where Eq. 16-19 are evaluated: 'edge' (default) = the edge publishes a state only on an "
        "event (both directions event-triggered); 'controller' = the paper's (the edge publishes every outer sample)")
    edge_check: Literal["outer", "sample"] = Field(
        "outer", description="edge placement: evaluate the trigger every outer sample or every inner (1 kHz) sample "
        "(ET only: TT publishes every outer sample, the periodic baseline, whatever this says)")
    edge_fallback: Literal["local", "hold"] = Field(
        "local", description="edge placement, a silent downlink: 'local' (default) = while an answer is overdue the "
        "edge computes v_x itself from the SMC law on its own samples (docs/deviations.md section 17); 'hold' = it "
        "keeps the controller's last setpoint (zero-order hold)")
    edge_model: bool = Field(True, description="edge placement: the lookahead runs the nominal model (else: "
                             "extrapolation of the sampled state over one round trip)")


class SimConfig(_Frozen):
    substeps: int = Field(2, ge=1)
    cycles: int = Field(1, ge=1)
