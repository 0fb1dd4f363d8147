"""What the CAN wire does to the inner loop's numbers: DBC scaling, rounding and range limits, nothing else.

`dbc_resolutions(fd)` reads the resolution (scale) of each feedback and voltage signal of the classic or the CAN FD
profile (FEEDBACK_FD and VOLTAGE_CMD_FD are finer) from protocol/sea.dbc and
`quantised` rounds a value to it, which is what a cantools encode/decode round trip does to an in-range value; the
offline closed loop uses them (`sea-hil simulate --quantise`) to show what quantisation alone costs in tracking error
(docs/can-protocol.md). `WireQuantiser` is the real round trip through the codec, used to check `quantised`.
"""
from __future__ import annotations

import functools

from sea_hil.protocol.can_codec import SeaCodec, load_database
from sea_hil.protocol.can_frames import Feedback, FeedbackAngle, FeedbackJoint1, FeedbackJoint2, VoltageCmd

Measurement = tuple[float, float, float, float, float, float, float, float]
Resolutions = tuple[float, float, float, float, float]
EXACT: Resolutions = (0.0, 0.0, 0.0, 0.0, 0.0)
_NODE = 1
_SIGNALS = {False: (("FEEDBACK_ANGLE", "theta1"), ("FEEDBACK_JOINT1", "omega1"), ("FEEDBACK_JOINT1", "delta1"),
                     ("FEEDBACK_JOINT1", "nut_vel1"), ("VOLTAGE_CMD", "voltage1")),
            True: (("FEEDBACK_FD", "theta1"), ("FEEDBACK_FD", "omega1"), ("FEEDBACK_FD", "delta1"),
                   ("FEEDBACK_FD", "nut_vel1"), ("VOLTAGE_CMD_FD", "voltage1"))}


@functools.cache
def dbc_resolutions(fd: bool = False) -> Resolutions:
    """(theta rad, omega rad/s, delta m, nut velocity m/s, voltage V) per LSB of the classic (`fd` False) or the CAN
    FD profile, from the DBC; joint 2 signals share joint 1's scale (checked by tests/test_quantisation.py)."""
    db = load_database()
    theta, omega, delta, nut_vel, voltage = (float(db.get_message_by_name(msg).get_signal_by_name(sig).scale)
                                             for msg, sig in _SIGNALS[bool(fd)])
    return theta, omega, delta, nut_vel, voltage


def quantised(value: float, lsb: float) -> float:
    """`value` rounded to the nearest multiple of `lsb` (a DBC raw integer times its scale); lsb <= 0: unchanged."""
    if lsb <= 0.0:
        return value
    return round(value / lsb) * lsb


class WireQuantiser:
    """Round trips through the DBC codec (saturate -> strict encode -> decode), as the driver and edge do; the
    measurement order is (theta1, theta2, omega1, omega2, delta1, delta2, nut_vel1, nut_vel2); `fd` picks the
    profile."""

    def __init__(self, fd: bool = False) -> None:
        self.codec = SeaCodec([_NODE], fd=fd)

    def measurement(self, meas: Measurement) -> Measurement:
        fb = Feedback(_NODE, 0, 0, (meas[0], meas[1]), (meas[2], meas[3]), (meas[4], meas[5]), (meas[6], meas[7]))
        sent, _ = self.codec.saturate(fb)
        frames = [self.codec.decode(m) for m in self.codec.encode_feedback(sent)]
        if len(frames) == 1:
            got = frames[0]
        else:
            a, j1, j2 = frames
            assert isinstance(a, FeedbackAngle) and isinstance(j1, FeedbackJoint1) and isinstance(j2, FeedbackJoint2)
            got = Feedback.from_parts(a, j1, j2)
        assert isinstance(got, Feedback)
        return (*got.theta_rad, *got.omega_rad_s, *got.delta_m, *got.nut_vel_m_s)

    def voltage(self, voltage_v: tuple[float, float]) -> tuple[float, float]:
        sent, _ = self.codec.saturate(VoltageCmd(_NODE, (float(voltage_v[0]), float(voltage_v[1])), 0))
        got = self.codec.decode(self.codec.encode(sent))
        assert isinstance(got, VoltageCmd)
        return got.voltage_v
