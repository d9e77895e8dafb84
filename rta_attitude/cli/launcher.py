"""The launcher of `rta-attitude launch` (cli/launch.py): four ROS 2 node processes over DDS, recorded.

    rta-attitude launch --scenario paper-example [--no-rta] [--preset robust|paper] [--realtime RTF]
                        --bag run.mcap [--out DIR] [--duration S] [-p KEY=VALUE ...]

Each node is its own OS process (`python -m rta_attitude.ros.<node>`, so its own DDS
participant), started with the same parameter file the core reads (`--params-file`) and the run's
knobs as `-p` overrides; the namespace is set by remapping `__ns`. The launcher itself starts no
ROS node. Sequence:

1. check the inputs (parameter file, scenario, overrides, bag path) with the core loader;
2. start the recorder, filter, controller (not with `--controller none`: then the plant waits for a node of
   the user's that publishes torque_des) and plant (children in their own sessions, each with
   `exit_with_parent`, so a launcher killed outright takes them along; output to log files, `--verbose`
   shows it);
3. wait for the plant to finish the scenario (it exits after its final `run_status`) and for the
   recorder to close the bag (it exits once every expected message is in);
4. stop the controller and filter with SIGINT (then SIGTERM; SIGKILL only as a last resort, which
   is reported as an error), check that no child survives and that no Fast DDS file the children
   used is left in /dev/shm (such files, when no live process maps them any more, are removed and
   reported as an error; a listening-port file, which writers of any DDS program share, is removed
   and noted in the run facts (`shm_ports_removed`), not blamed on the run);
5. summary from the recorded bag (`rta_attitude.recording.analysis`: states, commands and filter records as
   recorded; minima between samples by re-integrating each recorded step), printed with
   `metrics.format_summary` as `simulate` prints it, and written to `--out/summary.json` with a
   `launch` section (wall times, deadline misses, state -> torque_cmd latency, exit codes).

Ctrl-C stops the children cleanly. Returns 0 on a complete run, 1 otherwise.

Isolation: the children run with `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` (no traffic leaves the
machine; `--discovery subnet` lifts it) on `--domain-id` (default: $ROS_DOMAIN_ID, else
DEFAULT_DOMAIN_ID), and without ROS_STATIC_PEERS, so a run never talks to another robot on the network.
Node-only parameters given with `-p` are checked like the core's (type, choices, range) before any
process starts.

One module because its parts are one process lifecycle: `plan` checks every input and builds the
command lines that `launch` runs, and the /dev/shm bookkeeping needs the children's pids while they run
and is settled in the same `finally` that stops them.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from rta_attitude import config as config_module
from rta_attitude import topics
from rta_attitude.config.schema import Config
from rta_attitude.errors import ConfigError
from rta_attitude.files import output_file
from rta_attitude.ros.parameters import check_knob, flatten, nest

SHM_DIR = Path("/dev/shm")
STOP_TIMEOUT_S = 10.0
"""After SIGINT (and again after SIGTERM): how long a child may take to exit [s]."""
POLL_S = 0.05
SHM_SCAN_S = 0.5
"""How often the launcher notes which /dev/shm files its children use [s]."""
START_ORDER = (topics.RECORDER, topics.SCENE, topics.FILTER, topics.CONTROLLER, topics.PLANT)
"""Readers first; the scene has a process of its own only with `--scene node` (by default the recorder
hosts it)."""
DEFAULT_DOMAIN_ID = 0
"""ROS_DOMAIN_ID of the nodes when neither --domain-id nor $ROS_DOMAIN_ID says otherwise."""
DOMAIN_ID_RANGE = (0, 232)
"""Valid DDS domain ids for ROS 2 on Linux (0..101 and 215..232 avoid ephemeral ports; all <= 232 work)."""
DISCOVERY_RANGES = {"localhost": "LOCALHOST", "subnet": "SUBNET", "off": "OFF"}
"""--discovery -> ROS_AUTOMATIC_DISCOVERY_RANGE."""


@dataclass
class Child:
    """One node process."""

    role: str
    proc: subprocess.Popen[bytes]
    log_path: Path | None
    log_file: IO[bytes] | None = None
    signals: list[str] = field(default_factory=list)

    @property
    def name(self) -> str:
        return topics.EXECUTABLES[self.role]


# ----------------------------------------------------------------------------- arguments


def _overrides(args: argparse.Namespace) -> dict[str, Any]:
    """KEY=VALUE overrides (YAML-typed), plus --preset and --duration."""
    out = config_module.parse_overrides(args.param, "--param")
    if args.preset is not None:
        out["filter.preset"] = args.preset
    return out


CONTROLLER_PD, CONTROLLER_NONE = "pd", "none"
CONTROLLERS = (CONTROLLER_PD, CONTROLLER_NONE)
"""--controller: the run's pd_controller_node, or none (a node of the user's publishes torque_des; the plant
waits for it: its knob `external_controller`)."""


def controller_mode(args: argparse.Namespace) -> str:
    """`--controller` (CONTROLLERS; pd where the namespace has no such attribute)."""
    return str(getattr(args, "controller", CONTROLLER_PD))


def scene_mode(args: argparse.Namespace) -> str:
    """The run's scene (topics.SCENE_MODES): `--scene`, or none (topics.SCENE_OFF) with `--no-scene`."""
    return topics.SCENE_OFF if args.no_scene else args.scene


def _ros_value(value: Any) -> str:
    """A value as `-p name:=value` text (ROS parses it as YAML)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float, list)):
        return json.dumps(value)
    return str(value)


@dataclass(frozen=True)
class Plan:
    """What to run: checked configuration, scenario, and each node's command line."""

    cfg: Config
    scenario_key: str
    config_path: Path
    bag: Path
    temporary_bag: bool
    commands: dict[str, list[str]]
    steps: int
    timeout_s: float
    env: dict[str, str] = field(default_factory=dict)
    """ROS environment of the children (domain id, discovery range)."""


def plan(args: argparse.Namespace) -> Plan:
    """Check every input and build the node command lines.

    Raises:
        ConfigError: bad parameter file, scenario, override or bag path.
    """
    params, path = config_module.read_parameters(args.config)
    overrides = _overrides(args)
    knob_by_name = {k.name: k for k in topics.KNOBS}
    knob_names = set(knob_by_name)
    knobs = {k: check_knob(knob_by_name[k], v) for k, v in overrides.items() if k in knob_names}
    flat = dict(flatten(params))
    probe = config_module.from_parameters(params, source=str(path))
    scenario = probe.scenario(args.scenario)
    key = scenario.name
    if args.duration is not None:
        if not args.duration > 0:
            raise ConfigError(f"--duration must be > 0 s, got {args.duration}")
        overrides[f"scenarios.{key}.duration_s"] = float(args.duration)
    core = {k: v for k, v in overrides.items() if k not in knob_names}
    flat.update(core)
    cfg = config_module.from_parameters(nest(flat), source=str(path))
    cfg.spacecraft.require_three_wheels("rta-attitude launch")  # before any output is made
    scenario = cfg.scenario(key)
    if args.realtime is not None and not args.realtime > 0:
        raise ConfigError(f"--realtime must be > 0, got {args.realtime}")
    temporary = args.bag is None
    bag = Path(tempfile.mkdtemp(prefix="rta_launch_")) / "run.mcap" if temporary else Path(args.bag)
    if bag.exists() and not bag.is_dir() and not args.overwrite:
        raise ConfigError(f"--bag {bag} exists (pass --overwrite to replace it)")
    output_file(bag, "--bag")
    dt = cfg.filter.sample_time_s
    steps = round(scenario.duration_s / dt)
    if args.timeout is not None:
        timeout = float(args.timeout)
    elif args.realtime is not None:
        timeout = 60.0 + 1.5 * scenario.duration_s / args.realtime
    else:
        timeout = 60.0 + 0.1 * steps
    rta = not args.no_rta
    external = controller_mode(args) == CONTROLLER_NONE
    base = ["--ros-args", "--params-file", str(path), "-r", f"__ns:={args.namespace}",
            "-p", f"config_file:={path}", "-p", f"scenario:={key}", "-p", f"rta:={_ros_value(rta)}",
            "-p", "record:=true", "-p", f"scene:={scene_mode(args)}", "-p", "exit_with_parent:=true"]  # fmt: skip
    for name, value in core.items():
        base += ["-p", f"{name}:={_ros_value(value)}"]
    per_role: dict[str, dict[str, Any]] = {
        topics.PLANT: {"stepping": "realtime" if args.realtime is not None else "lockstep",
                       **({"real_time_factor": float(args.realtime)} if args.realtime is not None else {}),
                       **({"external_controller": True} if external else {})},
        topics.CONTROLLER: {"use_sim_time": True},
        topics.FILTER: {"use_sim_time": True},
        topics.RECORDER: {"use_sim_time": True, "bag_path": str(bag), "bag_overwrite": bool(args.overwrite)},
        topics.SCENE: {"use_sim_time": False},  # it draws by the stamps: no /clock reader, a message a step less
    }  # fmt: skip
    env = _environment(args)
    commands = {}
    for role in START_ORDER:
        if role == topics.SCENE and scene_mode(args) != topics.SCENE_NODE:
            continue  # none, or hosted by the recorder
        if role == topics.CONTROLLER and external:
            continue  # --controller none: the user's node publishes torque_des
        extra = dict(per_role[role])
        extra.update({k: v for k, v in knobs.items() if any(k == kn.name for kn in topics.knobs_for(role))})
        cmd = [sys.executable, "-m", topics.MODULES[role], *base]
        for name, value in extra.items():
            cmd += ["-p", f"{name}:={_ros_value(value)}"]
        commands[role] = cmd
    return Plan(cfg, key, path, bag, temporary, commands, steps, timeout, env)


def _environment(args: argparse.Namespace) -> dict[str, str]:
    """The ROS environment of the children: domain id, discovery range, no static peers.

    Raises:
        ConfigError: a domain id outside DOMAIN_ID_RANGE (from --domain-id or $ROS_DOMAIN_ID).
    """
    if args.domain_id is not None:
        domain, source = args.domain_id, "--domain-id"
    else:
        text = os.environ.get("ROS_DOMAIN_ID", "").strip()
        source = "$ROS_DOMAIN_ID"
        try:
            domain = int(text) if text else DEFAULT_DOMAIN_ID
        except ValueError:
            raise ConfigError(f"$ROS_DOMAIN_ID must be an integer in {DOMAIN_ID_RANGE[0]}..{DOMAIN_ID_RANGE[1]}, "
                              f"got {text!r}") from None
    if not DOMAIN_ID_RANGE[0] <= domain <= DOMAIN_ID_RANGE[1]:
        raise ConfigError(f"{source} must be in {DOMAIN_ID_RANGE[0]}..{DOMAIN_ID_RANGE[1]}, got {domain}")
    return {"ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": DISCOVERY_RANGES[args.discovery]}


# ----------------------------------------------------------------------------- processes


def _shm_files() -> set[str]:
    try:
        return {p.name for p in SHM_DIR.iterdir() if "fastrtps" in p.name or "fastdds" in p.name
                or "fast_datasharing" in p.name}
    except OSError:
        return set()


def _mapped_shm(pids: list[int] | None = None) -> set[str]:
    """Names of /dev/shm files that live processes (default: all) have mapped or open."""
    names: set[str] = set()
    for pid in (pids if pids is not None else [int(p) for p in os.listdir("/proc") if p.isdigit()]):
        try:
            with open(f"/proc/{pid}/maps") as f:
                names.update(Path(line.split()[-1]).name for line in f if "/dev/shm/" in line)
            for fd in os.listdir(f"/proc/{pid}/fd"):
                target = os.readlink(f"/proc/{pid}/fd/{fd}")
                if target.startswith("/dev/shm/"):
                    names.add(Path(target).name)
        except OSError:
            continue
    return names


def fastdds_files(pids: list[int]) -> set[str]:
    """The Fast DDS files in /dev/shm that processes `pids` use now, with their companions.

    Fast DDS names its shared-memory files (measured with rmw_fastrtps 8.4 / Fast DDS 2.14):
    `fastrtps_<16 hex>` (a participant's segment; random name, not the PID), `fastrtps_port<N>` (the
    ring buffer of a listening port, shared by every writer to it), `fast_datasharing_<guid>` (data
    sharing), each with a `<name>_el` file that its owner keeps locked while alive, and a named
    semaphore `sem.fastrtps_port<N>_mutex` per port, opened only briefly. Names carry no PID, so
    ownership is read from /proc/<pid>/maps and fd while the process lives; the `_el` and `sem.` names
    are added here because they are not always mapped.
    """
    names = {n for n in _mapped_shm(pids) if "fastrtps" in n or "fastdds" in n or "fast_datasharing" in n}
    for n in list(names):
        if not n.endswith("_el") and not n.startswith("sem."):
            names.add(n + "_el")
        if n.startswith("fastrtps_port") and not n.endswith("_el"):
            names.add(f"sem.{n}_mutex")
    return names


def stale_shm(ours: set[str]) -> list[str]:
    """Fast DDS files in /dev/shm that the run's processes used and no live process uses now
    (files of other DDS programs on the machine are never touched)."""
    left = _shm_files() & ours
    if not left:
        return []
    used = _mapped_shm()

    def base(name: str) -> str:  # the file a companion belongs to: X_el -> X, sem.X_mutex -> X
        if name.startswith("sem.") and name.endswith("_mutex"):
            return name[len("sem."):-len("_mutex")]
        return name[:-len("_el")] if name.endswith("_el") else name

    # a companion (lock file, port semaphore) goes only with its file: another program may share a port
    return sorted(n for n in left if n not in used and base(n) not in used)


def remove_stale_shm(ours: set[str]) -> list[str]:
    """Remove `stale_shm(ours)` (e.g. after a SIGKILL, which leaves Fast DDS files behind); returns the
    names that are gone now (a file that cannot be removed is not among them)."""
    removed = []
    for name in stale_shm(ours):
        try:
            (SHM_DIR / name).unlink()
        except FileNotFoundError:
            pass
        except OSError:
            continue
        removed.append(name)
    return removed


def _start(role: str, cmd: list[str], log_dir: Path | None, env: dict[str, str]) -> Child:
    log_path = log_dir / f"{topics.EXECUTABLES[role]}.log" if log_dir is not None else None
    log_file = open(log_path, "wb") if log_path is not None else None  # closed by launch()
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=log_file, stderr=subprocess.STDOUT if log_file
                            else None, env=env, start_new_session=True)  # fmt: skip
    return Child(role, proc, log_path, log_file)


def _signal(child: Child, sig: signal.Signals) -> None:
    if child.proc.poll() is None:
        child.signals.append(sig.name)
        try:
            child.proc.send_signal(sig)
        except ProcessLookupError:
            pass


def stop_children(children: list[Child], timeout_s: float = STOP_TIMEOUT_S) -> list[str]:
    """SIGINT every live child, then SIGTERM, then SIGKILL; returns problems (one line each)."""
    problems = []
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        alive = [c for c in children if c.proc.poll() is None]
        if not alive:
            break
        if sig == signal.SIGKILL:
            problems += [f"{c.name} ignored SIGINT and SIGTERM: killed (SIGKILL)" for c in alive]
        for c in alive:
            _signal(c, sig)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and any(c.proc.poll() is None for c in alive):
            time.sleep(POLL_S)
    for c in children:
        try:
            c.proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            problems.append(f"{c.name} (pid {c.proc.pid}) is still running")
    return problems


def _last_error(child: Child) -> str:
    """The node's last logged error (its last log line if none), without the log prefix; '' without a log."""
    if child.log_path is None or not child.log_path.exists():
        return ""
    lines = [line.strip() for line in child.log_path.read_text(errors="replace").splitlines() if line.strip()]
    errors = [line for line in lines if "[ERROR]" in line or line.startswith("ERROR")]
    line = (errors or lines or [""])[-1]
    return line.split("]: ", 1)[-1] if "]: " in line else line


# ----------------------------------------------------------------------------- run


def launch(p: Plan, log_dir: Path | None) -> tuple[list[str], dict[str, Any]]:
    """Start the nodes, wait for the run, stop them. Returns (problems, facts for the summary)."""
    env = dict(os.environ)
    env.update(p.env)
    if p.env.get("ROS_AUTOMATIC_DISCOVERY_RANGE") == "LOCALHOST":
        env.pop("ROS_STATIC_PEERS", None)
    env.setdefault("AMENT_PREFIX_PATH", sys.prefix)
    env["PYTHONUNBUFFERED"] = "1"
    env.setdefault("RCUTILS_COLORIZED_OUTPUT", "0")
    shm_before = _shm_files()
    ours: set[str] = set()
    last_scan = 0.0
    children: list[Child] = []
    problems: list[str] = []
    interrupted: list[int] = []
    previous = {s: signal.signal(s, lambda signum, frame: interrupted.append(signum))
                for s in (signal.SIGINT, signal.SIGTERM)}
    t0 = time.monotonic()
    facts: dict[str, Any] = {}
    try:
        for role in p.commands:  # START_ORDER
            children.append(_start(role, p.commands[role], log_dir, env))
        by_role = {c.role: c for c in children}
        plant, recorder = by_role[topics.PLANT], by_role[topics.RECORDER]
        deadline = t0 + p.timeout_s
        while True:
            if interrupted:
                problems.append("interrupted")
                break
            failed = [c for c in children if c.proc.poll() not in (None, 0)]
            if failed:
                for c in failed:
                    why = _last_error(c)
                    problems.append(f"{c.name} exited with code {c.proc.returncode}" + (f": {why}" if why else ""))
                break
            if plant.proc.poll() == 0 and "plant_s" not in facts:
                facts["plant_s"] = time.monotonic() - t0
            if plant.proc.poll() == 0 and recorder.proc.poll() == 0:
                break
            if time.monotonic() > deadline:
                problems.append(f"timed out after {p.timeout_s:g} s")
                break
            if time.monotonic() - last_scan > SHM_SCAN_S:  # which Fast DDS files are the run's
                last_scan = time.monotonic()
                ours |= (fastdds_files([c.proc.pid for c in children if c.proc.poll() is None]) - shm_before)
            time.sleep(POLL_S)
        facts["run_s"] = time.monotonic() - t0
    finally:
        problems += stop_children(children)
        for s, handler in previous.items():
            signal.signal(s, handler)
        for c in children:
            if c.log_file is not None:
                c.log_file.close()
    facts["exit_codes"] = {c.name: c.proc.returncode for c in children}
    facts["signals"] = {c.name: c.signals for c in children if c.signals}
    stale = remove_stale_shm(ours)
    # a port file (`fastrtps_port<N>`, its semaphore) is shared by every writer to that port, in any DDS
    # program on the machine: one left unused may be another program's (a process killed elsewhere), so it
    # is removed and noted, not blamed on the run; a participant's own segment (`fastrtps_<hex>`, unique)
    # or data-sharing file left behind is the run's leak
    leaked = [n for n in stale if not is_port_file(n)]
    if leaked:
        problems.append(f"Fast DDS files left in /dev/shm (removed): {', '.join(leaked)}")
    facts["shm_clean"] = not leaked
    facts["shm_ports_removed"] = [n for n in stale if is_port_file(n)]
    return problems, facts


def is_port_file(name: str) -> bool:
    """A Fast DDS listening-port file or its companions (lock file, semaphore): shared between programs."""
    return name.startswith(("fastrtps_port", "sem.fastrtps_port"))

