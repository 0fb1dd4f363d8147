"""The node runtime: the `Node` base (`node.py`), the real-time clock (`clock.py`) and the lockstep clock with all
lockstep logic (`lockstep.py`)."""
from sea_hil.runtime.clock import Clock, RealTimeClock, clock_for
from sea_hil.runtime.lockstep import LockstepClock
from sea_hil.runtime.node import Node

__all__ = ["Clock", "LockstepClock", "Node", "RealTimeClock", "clock_for"]
