"""`[verdict]`: when a finished session counts as `ok`, `degraded` or `invalid` (sea_hil/verdict/rules.py,
docs/verdict.md), and whether the inputs are checked before anything moves (sea_hil/input_check.py).

A drive fault (a soft-limit or watchdog latch) or an e-stop makes a run `invalid` whatever is set here: the limb did
not do what the session meant to test. The thresholds below are the most a counter may reach before the run is
`degraded`; counts are per session, `_pct` figures percent of the samples they refer to."""
from __future__ import annotations

from pydantic import Field

from sea_hil.config.base import _Frozen


class VerdictConfig(_Frozen):
    check_inputs: bool = Field(True, description="refuse a config whose start pose or trajectory leaves the drive's "
                               "soft limits, the end stops or the setpoint envelope (`sea-hil check` says why); false "
                               "= run it anyway (`--allow-unsafe-start` does the same for one command)")
    tick_miss_max_pct: float = Field(0.1, ge=0, description="driver ticks missed [% of ticks] the emulator may add "
                                     "on top of tick_miss_floor_factor x the host's floor (real time only)")
    tick_miss_floor_factor: float = Field(3.0, ge=0, description="multiple of the host's empty-loop floor (measured "
                                          "at start-up) a real-time session may miss before it is the emulator's")
    sync_miss_max_pct: float = Field(0.1, ge=0, description="cia402 profile: SYNC periods the edge's SYNC producer "
                                     "missed [% of periods] on top of sync_miss_floor_factor x the host's floor "
                                     "(real time only)")
    sync_miss_floor_factor: float = Field(3.0, ge=0, description="cia402 profile: multiple of the host's empty-loop "
                                          "floor a real-time session's SYNC producer may miss before it is the "
                                          "emulator's")
    floor_measure_s: float = Field(0.5, ge=0, description="real time: seconds of the empty 1 kHz loop run at "
                                   "start-up to measure the host's floor; 0 = not measured (floor taken as 0)")
    late_samples_max_pct: float = Field(1.0, ge=0, description="real time: feedback samples the edge left "
                                        "unanswered because they were older than safety.setpoint.max_sample_age_s "
                                        "[% of samples]")
    late_setpoints_max: int = Field(0, ge=0, description="setpoints dropped because the state they answer was older "
                                    "than safety.setpoint.max_answer_age_s")
    lost_setpoints_max: int = Field(0, ge=0, description="setpoints (or voltages) missing on arrival at the edge "
                                    "(sequence gaps before the downlink emulator: lost by the transport, not the "
                                    "link model)")
    lost_states_max: int = Field(0, ge=0, description="states missing on arrival at the controller beyond those the "
                                 "uplink model dropped")
    stale_setpoints_max: int = Field(0, ge=0, description="real time: setpoints dropped as stale or duplicated "
                                     "(lockstep re-sends repeat answers on purpose: not counted there)")
    envelope_rejections_max: int = Field(0, ge=0, description="setpoints the edge rejected as outside "
                                         "[safety.setpoint]")
    saturated_steps_max_pct: float = Field(1.0, ge=0, description="inner-loop steps whose voltage was clipped at "
                                           "plant.voltage_limit_v [% of steps]")
    rejections_max: int = Field(0, ge=0, description="each rejection counter (malformed frames and payloads, "
                                "foreign epochs, unexpected payloads, bus errors): the most it may count")
    recording_losses_max: int = Field(0, ge=0, description="messages the recorder dropped or could not write "
                                      "(summary.json recording.lost)")
