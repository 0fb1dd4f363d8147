"""Multi-process lockstep sessions for the guest tests: ``sea-hil plant|edge|record|controller`` as separate processes
on a real SocketCAN interface, optionally in network namespaces.

Separate processes rather than ``sea-hil run --can socketcan:vcan0`` (which also works in the guest): the plant and
the edge then share nothing but the kernel's vcan0, and the recorder taps it with a socket of its own, as in a
multi-host deployment. The session's trajectory is a short slice of the default gait (``write_gait_slice_config``)
to keep guest time small; the slice keeps the real gait's dynamics (only the duration is cut).
"""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from sea_hil.runtime.processes import end_process

REPO = Path(__file__).resolve().parents[2]
SAMPLE_STEP_S = 0.005        # CSV resolution of the gait slice (spline-interpolated by the controller)
STOP_TIMEOUT_S = 30.0
CONNECT_TIMEOUT_S = 60.0
RUN_TIMEOUT_S = 400.0
SLICE_S = 1.0                # the lockstep node sessions' gait slice (tests/socketcan/conftest.py: gait_slice)


def sea_hil_cmd(*args: str, netns: str | None = None) -> list[str]:
    """argv running ``sea-hil ARGS`` with this interpreter, inside network namespace ``netns`` if given."""
    cmd = [sys.executable, "-m", "sea_hil.cli", *args]
    return ["ip", "netns", "exec", netns, *cmd] if netns else cmd


def write_gait_slice_config(directory: Path, duration_s: float, paper: bool = True) -> Path:
    """Write ``gait-slice.csv`` (the default gait's first ``duration_s``) and ``session.toml`` using it; -> TOML.
    `paper`: the paper's scheme (trigger at the controller, no compensation; the counts these tests assert are its),
    else the default one (no [trigger] / [controller] tables: the caller may append them)."""
    from sea_hil.config.loader import load_config
    from sea_hil.controller.trajectory import GaitTrajectory
    gait = GaitTrajectory(load_config().trajectory.period_s)
    rows = ["t,theta1,theta2"]
    for i in range(int(round(duration_s / SAMPLE_STEP_S)) + 1):
        t_s = i * SAMPLE_STEP_S
        q = gait.sample(t_s).theta_rad
        rows.append(f"{t_s:.6f},{q[0]!r},{q[1]!r}")
    csv_path = directory / "gait-slice.csv"
    csv_path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    toml_path = directory / "session.toml"
    # no lead-in: the slice is short and the guest slow; every handled state is in the measured cycle
    scheme = '\n[trigger]\nplacement = "controller"\n\n[controller]\ncompensation = "none"\n' if paper else ""
    toml_path.write_text(f'[trajectory]\nkind = "csv"\ncsv_path = "{csv_path}"\nlead_in_s = 0.0\n' + scheme,
                         encoding="utf-8")
    return toml_path


def write_client_config(directory: Path) -> Path:
    """A config making a node a Zenoh *client*: a peer (the edge) routes every peer's traffic to its clients,
    so a recorder connected as client sees the remote controller's messages too."""
    path = directory / "client.toml"
    path.write_text('[zenoh]\nmode = "client"\n', encoding="utf-8")
    return path


class NodeGroup:
    """Processes started by a test; each one's output goes to ``<log_dir>/<name>.log``. A context manager: on exit
    (also when the test fails) every process still running is terminated (then killed) and reaped."""

    def __init__(self, log_dir: Path) -> None:
        self.log_dir = log_dir
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self._logs: list[IO[bytes]] = []

    def start(self, name: str, cmd: list[str]) -> subprocess.Popen[bytes]:
        """Start ``cmd`` as node ``name`` (cwd = repository root)."""
        log = open(self.log_dir / f"{name}.log", "wb")  # noqa: SIM115 - closed in close()
        self._logs.append(log)
        proc = subprocess.Popen(cmd, cwd=REPO, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT)
        self.procs[name] = proc
        return proc

    def stop(self, name: str) -> int:
        """SIGTERM node ``name`` (a clean shutdown) and return its exit status; kill it if it does not exit."""
        status = end_process(self.procs[name], STOP_TIMEOUT_S)
        if status == -signal.SIGKILL:
            raise AssertionError(f"{name} ignored SIGTERM for {STOP_TIMEOUT_S} s:\n{self.output(name)}")
        return status

    def output(self, name: str) -> str:
        """What node ``name`` printed so far."""
        return (self.log_dir / f"{name}.log").read_text(errors="replace")

    def result(self, name: str) -> dict[str, Any]:
        """Node ``name``'s own result: the last JSON line it printed (``--json``; its log lines are not JSON)."""
        lines = [ln for ln in self.output(name).splitlines() if ln.startswith("{")]
        if not lines:
            raise AssertionError(f"{name} printed no --json result:\n{self.output(name)[-3000:]}")
        return dict(json.loads(lines[-1]))

    def outputs(self) -> str:
        """Every node's output, for assertion messages."""
        return "\n".join(f"--- {n}:\n{self.output(n)[-3000:]}" for n in self.procs)

    def close(self) -> None:
        """End and reap every process still running; close the log files."""
        for proc in self.procs.values():
            end_process(proc, STOP_TIMEOUT_S)
        for log in self._logs:
            log.close()

    def __enter__(self) -> NodeGroup:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def tcp_sockets(port: int, state: str, netns: str | None) -> int:
    """Number of TCP sockets in ``state`` (ss syntax: listening, established) with local port ``port``."""
    cmd = ["ss", "-Htan", "state", state, f"( sport = :{port} )"]
    cmd = ["ip", "netns", "exec", netns, *cmd] if netns else cmd
    out = subprocess.run(cmd, check=True, stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=30)
    return sum(1 for line in out.stdout.splitlines() if line.strip())


def wait_for_sockets(port: int, state: str, count: int, netns: str | None, proc: subprocess.Popen[bytes],
                     timeout_s: float = CONNECT_TIMEOUT_S) -> None:
    """Block until ``count`` TCP sockets on local ``port`` are in ``state`` (polling ``ss``), or raise after
    ``timeout_s`` or as soon as ``proc`` (the node owning the port) exits."""
    deadline = time.monotonic() + timeout_s
    while tcp_sockets(port, state, netns) < count:
        if proc.poll() is not None:
            raise AssertionError(f"the node exited ({proc.returncode}) before {count} {state} socket(s) on {port}")
        if time.monotonic() > deadline:
            raise AssertionError(f"fewer than {count} {state} socket(s) on port {port} within {timeout_s} s")
        try:
            proc.wait(timeout=0.2)   # bounded wait on the node doubles as the poll interval
        except subprocess.TimeoutExpired:
            pass


RECORDER_READY = "sea-hil record: recording "   # printed once its subscribers are declared (commands/record.py)


def wait_for_output(nodes: NodeGroup, name: str, line: str, timeout_s: float = CONNECT_TIMEOUT_S) -> None:
    """Block until node ``name`` has printed ``line`` (polling its log), or raise after ``timeout_s`` or as soon as
    it exits."""
    proc = nodes.procs[name]
    deadline = time.monotonic() + timeout_s
    while line not in nodes.output(name):
        if proc.poll() is not None:
            raise AssertionError(f"{name} exited ({proc.returncode}) before printing {line!r}")
        if time.monotonic() > deadline:
            raise AssertionError(f"{name} did not print {line!r} within {timeout_s} s")
        try:
            proc.wait(timeout=0.2)   # bounded wait on the node doubles as the poll interval
        except subprocess.TimeoutExpired:
            pass


@dataclass(frozen=True)
class NodeSession:
    """Where the nodes of one lockstep session run. Plant, edge and recorder share the CAN interface (and
    ``bus_netns``); the controller runs in ``controller_netns`` and connects to the edge's ``listen`` endpoint."""

    config: Path
    client_config: Path
    can: str
    listen_host: str
    port: int
    bus_netns: str | None = None
    controller_netns: str | None = None
    controller: str = "et"
    timeout_s: float = 300.0

    @property
    def endpoint(self) -> str:
        return f"tcp/{self.listen_host}:{self.port}"


@dataclass(frozen=True)
class NodeSessionResult:
    """What one node session left: its summary (also written to ``out/summary.json``), the recording, the plant's
    closing report line (ticks, overruns) and the edge's and the controller's own results (``--json``)."""

    summary: dict[str, Any]
    data: Any   # sea_hil.recorder.writer.SessionData
    plant_report: str
    nodes: dict[str, dict[str, Any]]


def run_node_session(s: NodeSession, out: Path) -> NodeSessionResult:
    """Run one lockstep cycle with plant, edge, recorder and controller as separate processes, stop them in order
    (the edge before the recorder, so that its final stats are recorded) and summarise ``out/session.mcap``."""
    cfg, mcap = str(s.config), out / "session.mcap"
    with NodeGroup(out) as nodes:
        edge = nodes.start("edge", sea_hil_cmd("edge", "--can", s.can, "--lockstep", "--listen", s.endpoint,
                                               "--config", cfg, "--json", netns=s.bus_netns))
        try:
            wait_for_sockets(s.port, "listening", 1, s.bus_netns, edge)   # a Zenoh client does not retry
            nodes.start("record", sea_hil_cmd("record", "--can", s.can, "--out", str(mcap), "--connect", s.endpoint,
                                              "--config", str(s.client_config), netns=s.bus_netns))
            wait_for_sockets(s.port, "established", 1, s.bus_netns, edge)  # the recorder is in before the controller
            # connected is not subscribed: a recorder that only connects is a Zenoh client, whose subscriptions follow
            # its connection (a first tracking record was missed once in the guest without this wait)
            wait_for_output(nodes, "record", RECORDER_READY)
        except AssertionError as err:
            raise AssertionError(f"{err}\n{nodes.outputs()}") from None
        ctl = nodes.start("controller", sea_hil_cmd("controller", "--controller", s.controller, "--cycles", "1",
                                                    "--lockstep", "--connect", s.endpoint, "--config", cfg,
                                                    "--timeout", str(s.timeout_s), "--json",
                                                    netns=s.controller_netns))
        try:
            # the plant last: no state exists before the controller's session is open, so the recorder's
            # subscription has reached the controller (across the netem link too) before its first record; with
            # the plant first, the controller answered the re-sent anchor state within a few ms of connecting and
            # its INITIAL tracking record sometimes went out before that (seen twice in the guest)
            wait_for_sockets(s.port, "established", 2, s.bus_netns, edge)
        except AssertionError as err:
            raise AssertionError(f"{err}\n{nodes.outputs()}") from None
        nodes.start("plant", sea_hil_cmd("plant", "--can", s.can, "--lockstep", "--config", cfg, netns=s.bus_netns))
        try:
            status = ctl.wait(timeout=s.timeout_s + STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"controller did not finish in {s.timeout_s} s:\n{nodes.outputs()}") from None
        assert status == 0, f"controller exited with {status}:\n{nodes.outputs()}"
        for name in ("edge", "plant", "record"):
            assert nodes.stop(name) == 0, f"{name} did not exit cleanly:\n{nodes.outputs()}"
        plant_lines = nodes.output("plant").strip().splitlines()
        results = {name: nodes.result(name) for name in ("edge", "controller")}
    from sea_hil.recorder.reader import read_session
    from sea_hil.report.session_summary import session_summary
    from sea_hil.report.summary import write_summary
    data = read_session(mcap)
    # as `sea-hil run` and `report` summarise a recording: the file against the nodes' own counters (issue 32), and
    # the verdict judged with it
    summary = session_summary(data, s.controller)
    summary.update(lockstep=True, inner="edge")
    write_summary(out / "summary.json", summary)
    return NodeSessionResult(summary, data, plant_lines[-1] if plant_lines else "", results)


def lockstep_run_summary(config: Path, out: Path, controller: str = "et") -> dict[str, Any]:
    """summary.json of ``sea-hil run --lockstep`` on ``config`` (plant, edge and recorder on the embedded virtual
    bus): what a lockstep node session's summary must equal in every deterministic field."""
    cmd = sea_hil_cmd("run", "--lockstep", "--quiet", "--controller", controller, "--cycles", "1", "--config",
                      str(config), "--out", str(out))
    result = subprocess.run(cmd, stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=RUN_TIMEOUT_S,
                            check=False)
    assert result.returncode == 0, result.stderr[-3000:]
    return dict(json.loads((out / "summary.json").read_text()))


@dataclass(frozen=True)
class GaitSlice:
    """The lockstep node sessions' shared config (a ``duration_s`` slice of the gait, paper scheme) and the summary
    ``sea-hil run --lockstep`` writes for it (``reference``): run once per guest session (≈ 60 s in the guest)."""

    config: Path
    duration_s: float
    reference: dict[str, Any]
