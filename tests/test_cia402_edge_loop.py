"""The edge's CANopen master core (`controller/cia402_master.py`) against the CiA 402 drive core, in lockstep in one
process: start-up (reset communication, SDO configuration, the state walk, NMT start), then the edge's backstepping
inner loop on every SYNC, the voltages in RPDO 3. The same loop over the sea profile's firmware core with the
unquantised feedback is the reference: the CiA 402 transport (urad / nm scaling, a voltage acting on arrival) must
give the same motion up to its quantisation."""
from __future__ import annotations

from sea_hil.config.loader import load_config
from sea_hil.controller.cia402_master import Cia402Master
from sea_hil.controller.cia402_master import Frame as MasterFrame
from sea_hil.controller.inner import InnerLoop
from sea_hil.mechanics import limb_params
from sea_hil.plant_emulator.canopen_slave import Frame as SlaveFrame
from sea_hil.plant_emulator.cia402_drive import Cia402Limb
from sea_hil.plant_emulator.disturbance import make_disturbance
from sea_hil.plant_emulator.driver import DriverCore
from sea_hil.protocol.can_frames import VoltageCmd

MS = 1_000_000
STEPS = 400
PULSE_M, PULSE_STEPS = (0.0003, -0.0002), 60   # a deflection pulse on top of the initial (gravity) deflection


def setpoint(k: int, rest: tuple[float, float]) -> tuple[float, float]:
    if k > PULSE_STEPS:
        return rest
    return (rest[0] + PULSE_M[0], rest[1] + PULSE_M[1])


def pump(limb: Cia402Limb, master: Cia402Master, frames: list[MasterFrame], t_ns: int) -> None:
    """Deliver master frames to the drive and the drive's answers to the master until the bus is quiet."""
    pending = list(frames)
    while pending:
        f = pending.pop(0)
        for out in limb.receive(SlaveFrame(f.can_id, f.data), t_ns):
            pending += master.receive(MasterFrame(out.can_id, out.data))


def test_master_start_up_and_inner_loop_on_sync() -> None:
    cfg = load_config(overrides={"can": {"profile": "cia402"}})
    p = limb_params(cfg.plant)
    limb, master = Cia402Limb.create(cfg, (1, 2)), Cia402Master((1, 2))
    limb.start(0)
    pump(limb, master, master.start(), 0)
    assert master.phase == "run" and master.enabled and master.counters.sdo_aborts == 0
    inner = InnerLoop(cfg, p, tuple(cfg.plant.initial_theta_rad))
    rest = limb.driver.feedback().delta_m
    theta = []
    for k in range(1, STEPS + 1):
        pump(limb, master, master.sync(), k * MS)
        m = master.measurement()
        assert m is not None
        theta.append(m[:2])
        inner.hold(setpoint(k, rest), (0.0, 0.0))
        pump(limb, master, master.command(inner.voltage(m)), k * MS)
    assert master.counters.incomplete_syncs == 0 and master.counters.emcys == 0 and master.counters.faults == 0

    ref = DriverCore.create(1, p, 1e-3, 0.1, cfg.sim.substeps, tuple(cfg.plant.initial_theta_rad),
                            make_disturbance(cfg.disturbance))
    ref_inner = InnerLoop(cfg, p, tuple(cfg.plant.initial_theta_rad))
    ref.step()
    ref_theta = []
    for k in range(1, STEPS + 1):
        fb = ref.feedback()
        ref_inner.hold(setpoint(k, rest), (0.0, 0.0))
        ref_theta.append(fb.theta_rad)
        m = (*fb.theta_rad, *fb.omega_rad_s, *fb.delta_m, *fb.nut_vel_m_s)
        ref.handle(VoltageCmd(1, ref_inner.voltage(m), 0), 0)
        ref.step()
    moved = max(abs(a[j] - theta[0][j]) for a in theta for j in range(2))
    deviation = max(abs(a[j] - b[j]) for a, b in zip(theta, ref_theta, strict=True) for j in range(2))
    print(f"cia402 inner loop: moved {moved:.4f} rad, max deviation from the unquantised loop {deviation:.2e} rad")
    assert moved > 0.005 and deviation < 1e-4


def test_the_master_rejects_and_counts_short_frames_of_its_nodes() -> None:
    """A truncated SDO reply, statusword or TPDO of the limb's nodes is counted, never raised (the sea profile's
    edge does the same with malformed frames)."""
    master = Cia402Master((1, 2))
    bad = [MasterFrame(0x581, b""), MasterFrame(0x181, b"\x01"), MasterFrame(0x282, b"\x00" * 3),
           MasterFrame(0x381, b"\x00" * 7)]
    assert all(master.receive(f) == [] for f in bad)
    assert master.counters.rejected_frames == len(bad)
    assert master.measurement() is None
