"""The node runtime: the `Node` base (`node.py`), the real-time clock (`clock.py`) and the lockstep clock with all
lockstep logic (`lockstep.py`)."""
