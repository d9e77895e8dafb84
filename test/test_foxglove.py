"""`rta-attitude foxglove` and the shipped Foxglove/Lichtblick layout.

Live server (marked dds): an rclpy publisher in this process sends the run's `state` (JointState) and
`filter_status` (DiagnosticArray) with the run's QoS over Fast DDS; the command runs as a subprocess; the test is
a Foxglove WebSocket client written here on the standard library (handshake, masked frames), which offers the
subprotocol `foxglove.websocket.v1` and decodes the binary MessageData payloads with rosbags' own CDR reader and
its own Jazzy type store (never rclpy). Every wait is a condition with a deadline. The server completes the
WebSocket closing handshake (a Close frame back, not a dropped connection), and finds the message definitions
without AMENT_PREFIX_PATH, as on a plain pip install into a venv.

Layout (no DDS): config/foxglove_layout.json is what `recording.layout` writes for the default configuration; it is
a react-mosaic tree whose every panel has a config and a title under both apps' keys; every message path names a
topic the run publishes (rta_attitude.topics), resolves field by field in the topic's message type, and filters on
filter_status entry names and keys the filter writes; every constraint's margin is plotted in its unit (cones in
rad, temperature in K, battery in J, body rates and wheel speeds in rad/s, one unit to a plot) with its
limit lines; a configuration with a third cone gets its series.
"""

from __future__ import annotations

import base64
import json
import math
import os
import queue
import re
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from rta_attitude import config, topics
from rta_attitude.dynamics.state import STATE_NAMES
from rta_attitude.recording import layout as layout_module

ROOT = Path(__file__).resolve().parents[1]
LAYOUT_FILE = ROOT / "config" / "foxglove_layout.json"
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
CFG = config.load()
CONSTRAINT_NAMES = CFG.constraint_names
DEADLINE_S = 60.0
"""Safety net of every wait (a loaded machine starts rclpy slowly); not a timing."""

RUN_TOPICS: dict[str, str] = {
    (n if n.startswith("/") else f"{topics.DEFAULT_NAMESPACE}/{n}"): spec.type_name
    for n, spec in topics.TOPICS.items()
} | {topics.DIAGNOSTICS: "diagnostic_msgs/msg/DiagnosticArray"}
"""Every topic a run publishes (default namespace) -> its type, and /diagnostics (every node's summary)."""


# ----------------------------------------------------------------------------- a Foxglove client (stdlib only)

LEGACY_SUBPROTOCOL = "foxglove.websocket.v1"
SDK_SUBPROTOCOL = "foxglove.sdk.v1"
OP_MESSAGE_DATA, OP_TIME = 0x01, 0x02


class WsClient:
    """A minimal RFC 6455 client: enough for the Foxglove protocol (text and binary frames, ping, close)."""

    def __init__(self, port: int, subprotocols: list[str]) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=DEADLINE_S)
        key = base64.b64encode(os.urandom(16)).decode()
        request = (f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                   f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                   f"Sec-WebSocket-Protocol: {', '.join(subprotocols)}\r\n\r\n")
        self.sock.sendall(request.encode())
        head = b""
        while b"\r\n\r\n" not in head:
            chunk = self.sock.recv(1)
            if not chunk:
                raise ConnectionError(f"handshake: connection closed after {head!r}")
            head += chunk
        lines = head.decode("latin-1").split("\r\n")
        self.status = int(lines[0].split()[1])
        self.headers = {k.strip().lower(): v.strip() for k, _, v in (ln.partition(":") for ln in lines[1:] if ln)}
        self.subprotocol = self.headers.get("sec-websocket-protocol")

    def _exact(self, n: int) -> bytes:
        data = b""
        while len(data) < n:
            chunk = self.sock.recv(n - len(data))
            if not chunk:
                raise ConnectionError("connection closed")
            data += chunk
        return data

    def send(self, opcode: int, payload: bytes) -> None:
        mask = os.urandom(4)
        n = len(payload)
        head = bytes([0x80 | opcode])
        head += bytes([0x80 | n]) if n < 126 else bytes([0x80 | 126]) + struct.pack(">H", n) if n < 65536 \
            else bytes([0x80 | 127]) + struct.pack(">Q", n)
        self.sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload)))

    def send_json(self, msg: dict[str, Any]) -> None:
        self.send(0x1, json.dumps(msg).encode())

    def frame(self) -> tuple[int, bytes]:
        """The next frame from the server (unmasked): its first header byte (FIN, opcode) and its payload."""
        b0, b1 = self._exact(2)
        n = b1 & 0x7F
        if n == 126:
            n = struct.unpack(">H", self._exact(2))[0]
        elif n == 127:
            n = struct.unpack(">Q", self._exact(8))[0]
        return b0, self._exact(n)

    def recv(self) -> str | bytes:
        """The next whole text (str) or binary (bytes) message."""
        parts: list[bytes] = []
        kind = 0
        while True:
            b0, payload = self.frame()
            opcode = b0 & 0x0F
            if opcode == 0x9:
                self.send(0xA, payload)
                continue
            if opcode == 0x8:
                raise ConnectionError("server closed the connection")
            if opcode in (0x1, 0x2):
                kind = opcode
            if opcode in (0x0, 0x1, 0x2):
                parts.append(payload)
                if b0 & 0x80:
                    data = b"".join(parts)
                    return data.decode() if kind == 0x1 else data

    def close(self) -> None:
        try:
            self.send(0x8, struct.pack(">H", 1000))
        except OSError:
            pass
        self.sock.close()


class FoxgloveClient:
    """Protocol state: server info, advertised channels, messages per channel."""

    def __init__(self, ws: WsClient) -> None:
        self.ws = ws
        self.server_info: dict[str, Any] | None = None
        self.channels: dict[int, dict[str, Any]] = {}
        self.messages: dict[int, list[tuple[int, bytes]]] = {}
        self.sub_to_channel: dict[int, int] = {}
        self.pending: set[int] = set()
        self.next_sub = 1

    def channel(self, topic: str) -> dict[str, Any] | None:
        return next((c for c in self.channels.values() if c["topic"] == topic), None)

    def subscribe(self, channel_ids: list[int]) -> None:
        subs = []
        for cid in channel_ids:
            subs.append({"id": self.next_sub, "channelId": cid})
            self.sub_to_channel[self.next_sub] = cid
            self.next_sub += 1
        self.ws.send_json({"op": "subscribe", "subscriptions": subs})

    def handle(self, frame: str | bytes) -> None:
        if isinstance(frame, bytes):
            if frame[0] == OP_MESSAGE_DATA:
                sub_id, log_time = struct.unpack_from("<IQ", frame, 1)
                self.messages.setdefault(self.sub_to_channel[sub_id], []).append((log_time, frame[13:]))
            return
        msg = json.loads(frame)
        if msg["op"] == "serverInfo":
            self.server_info = msg
        elif msg["op"] == "advertise":
            self.channels.update({c["id"]: c for c in msg["channels"]})
        elif msg["op"] == "status":
            # the SDK sends `advertise` before it registers the channel for this client: a subscribe that
            # follows at once may be refused ("Unknown channel ID"); a client retries, as the apps do
            m = re.fullmatch(r"Unknown channel ID: (\d+)", msg.get("message", ""))
            if m and int(m.group(1)) in self.channels:
                self.pending.add(int(m.group(1)))

    def pump_until(self, done: Callable[[], bool], what: str) -> None:
        deadline = time.monotonic() + DEADLINE_S
        while not done():
            if time.monotonic() > deadline:
                pytest.fail(f"no {what} within {DEADLINE_S} s")
            self.handle(self.ws.recv())
            if self.pending:
                retry, self.pending = sorted(self.pending), set()
                self.subscribe(retry)


# ----------------------------------------------------------------------------- processes


def plain_venv_env() -> dict[str, str]:
    """The environment of a plain `pip install` into a venv: no AMENT_PREFIX_PATH (which conftest.py and the
    launcher set)."""
    return {k: v for k, v in os.environ.items() if k != "AMENT_PREFIX_PATH"}


class Server:
    """`rta-attitude foxglove` as a subprocess; stdout lines collected by a thread."""

    def __init__(self, *args: str, env: dict[str, str] | None = None) -> None:
        self.popen = subprocess.Popen([sys.executable, "-m", "rta_attitude.cli", "foxglove", *args],
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                                      env={**(os.environ if env is None else env), "PYTHONUNBUFFERED": "1"})
        self.lines: queue.Queue[str] = queue.Queue()
        self.stderr: list[str] = []
        self.threads = [threading.Thread(target=self._pump, args=(self.popen.stdout, self.lines.put), daemon=True),
                        threading.Thread(target=self._pump, args=(self.popen.stderr, self.stderr.append),
                                         daemon=True)]
        for t in self.threads:
            t.start()

    @staticmethod
    def _pump(stream: Any, sink: Callable[[str], None]) -> None:
        for line in stream:
            sink(line)

    def port(self, prefix: str = "foxglove server listening on ") -> int:
        deadline = time.monotonic() + DEADLINE_S
        while time.monotonic() < deadline:
            try:
                line = self.lines.get(timeout=0.2)
            except queue.Empty:
                if self.popen.poll() is not None:
                    break
                continue
            if line.startswith(prefix):
                return int(line.strip().rsplit(":", 1)[1])
        pytest.fail(f"server printed no {prefix!r} (rc {self.popen.poll()}):\n{''.join(self.stderr)}")

    def stop(self, sig: signal.Signals) -> int:
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
        try:
            rc = self.popen.wait(timeout=DEADLINE_S)
        except subprocess.TimeoutExpired:
            self.popen.kill()
            self.popen.wait()
            pytest.fail(f"the server did not stop within {DEADLINE_S} s of {sig.name}")
        for t in self.threads:
            t.join(timeout=DEADLINE_S)
        return rc


@pytest.fixture
def servers() -> Iterator[Callable[..., Server]]:
    started: list[Server] = []

    def start(*args: str, env: dict[str, str] | None = None) -> Server:
        started.append(Server(*args, env=env))
        return started[-1]

    yield start
    for s in started:
        if s.popen.poll() is None:
            s.stop(signal.SIGINT)


CLOCK_START_NS = 1_000 * 10**9


def state_values() -> list[float]:
    from rta_attitude.dynamics.state import STATE_NAMES

    return [0.125 * (i + 1) - 1.0 for i in range(len(STATE_NAMES))]


@pytest.fixture
def run_publisher() -> Iterator[dict[str, Any]]:
    """The run's `state` and `filter_status` with the run's QoS, published every 50 ms from a thread."""
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node

    from rta_attitude.dynamics.state import STATE_NAMES
    from rta_attitude.ros import convert, interface

    context = Context()
    rclpy.init(context=context)
    node = Node("foxglove_test_publisher", context=context, namespace=topics.DEFAULT_NAMESPACE)
    pubs = {name: node.create_publisher(interface.msg_class(topics.TOPICS[name].type_name), name,
                                        interface.qos_profile(topics.TOPICS[name].qos, 2.0))
            for name in (topics.STATE, topics.FILTER_STATUS, topics.RUN_STATUS, topics.CLOCK)}
    # run_status is latched (transient-local): published once, before any server reads it
    pubs[topics.RUN_STATUS].publish(convert.run_status_msg(5_000_000_000, topics.RUN_RUNNING, {"commands": 7}))
    import numpy as np

    state = convert.state_msg(np.array(state_values()), 12_000_000_345)
    diag = interface.msg_class("diagnostic_msgs/msg/DiagnosticArray")()
    diag.header.stamp = convert.stamp(12_000_000_345)
    status_cls = interface.msg_class("diagnostic_msgs/msg/DiagnosticStatus")
    kv_cls = interface.msg_class("diagnostic_msgs/msg/KeyValue")
    diag.status = [status_cls(level=b"\x01", name=topics.QP_STATUS_NAME, message="solved",
                              hardware_id=topics.STATUS_HARDWARE_ID,
                              values=[kv_cls(key="u_des_x", value="0.5"), kv_cls(key="u_x", value="0.25")])]
    diag.status += [status_cls(level=b"\x00", name=n, message="ok", hardware_id=topics.STATUS_HARDWARE_ID,
                               values=[kv_cls(key="h", value=repr(0.5 + i))]) for i, n in enumerate(CONSTRAINT_NAMES)]
    stop = threading.Event()

    def loop() -> None:
        clock_ns = CLOCK_START_NS
        while not stop.wait(0.05):
            pubs[topics.STATE].publish(state)
            pubs[topics.FILTER_STATUS].publish(diag)
            clock_ns += 10_000_000
            pubs[topics.CLOCK].publish(convert.clock_msg(clock_ns))

    thread = threading.Thread(target=loop, daemon=True)
    thread.start()
    try:
        yield {"names": list(STATE_NAMES), "stamp_ns": 12_000_000_345}
    finally:
        stop.set()
        thread.join(timeout=DEADLINE_S)
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def decode(type_name: str, raw: bytes) -> Any:
    return TYPESTORE.deserialize_cdr(raw, type_name)


# ----------------------------------------------------------------------------- live tests


@pytest.mark.dds
def test_live_state_and_filter_status_decode_with_an_independent_reader(
        run_publisher: dict[str, Any], servers: Callable[..., Server]) -> None:
    server = servers("--port", "0", "--legacy-port", "0", "--topics", "/rta/.*", "--exclude", "/rta/torque_.*",
                     "--rescan-period", "0.3")
    port = server.port()
    legacy_port = server.port("foxglove server (foxglove.websocket.v1 relay) listening on ")
    # the SDK's port answers foxglove.sdk.v1 (the protocol's current name) and refuses the old name alone
    for offered, status, chosen in (([SDK_SUBPROTOCOL], 101, SDK_SUBPROTOCOL), ([LEGACY_SUBPROTOCOL], 400, None)):
        probe = WsClient(port, offered)
        assert (probe.status, probe.subprotocol) == (status, chosen)
        probe.close() if status == 101 else probe.sock.close()
    ws = WsClient(legacy_port, [LEGACY_SUBPROTOCOL])
    assert (ws.status, ws.subprotocol) == (101, LEGACY_SUBPROTOCOL), ws.headers
    client = FoxgloveClient(ws)
    try:
        client.pump_until(lambda: client.server_info is not None, "serverInfo")
        wanted = {f"/rta/{topics.STATE}": "sensor_msgs/msg/JointState",
                  f"/rta/{topics.FILTER_STATUS}": "diagnostic_msgs/msg/DiagnosticArray",
                  f"/rta/{topics.RUN_STATUS}": "diagnostic_msgs/msg/DiagnosticArray"}
        client.pump_until(lambda: all(client.channel(t) for t in wanted), "advertise of state and filter_status")
        for topic, type_name in wanted.items():
            chan = client.channel(topic)
            assert chan is not None
            assert (chan["encoding"], chan["schemaName"], chan["schemaEncoding"]) == ("cdr", type_name, "ros2msg")
            parsed = get_types_from_msg(chan["schema"], type_name)
            assert parsed[type_name][1] == TYPESTORE.fielddefs[type_name][1], "schema is the Jazzy definition"
        ids = [client.channel(t)["id"] for t in wanted]  # type: ignore[index]
        client.subscribe(ids)
        client.pump_until(lambda: all(len(client.messages.get(i, [])) >= (1 if i == ids[2] else 2) for i in ids),
                          "messages on state and filter_status, and the latched run_status")
        assert not any(c["topic"] in ("/clock", "/rosout", "/parameter_events") for c in client.channels.values()), \
            "--topics"
        # Ctrl-C with a client connected and subscribed: exit 0
        assert server.stop(signal.SIGINT) == 0, "".join(server.stderr)
        assert "Traceback" not in "".join(server.stderr)
    finally:
        ws.close()

    log_time, raw = client.messages[ids[0]][-1]
    state = decode("sensor_msgs/msg/JointState", raw)
    assert list(state.name) == run_publisher["names"]
    assert state.position.tolist() == state_values()
    assert state.header.stamp.sec * 10**9 + state.header.stamp.nanosec == run_publisher["stamp_ns"]
    assert log_time == run_publisher["stamp_ns"], "log time is header.stamp"
    _, raw = client.messages[ids[1]][-1]
    diag = decode("diagnostic_msgs/msg/DiagnosticArray", raw)
    by_name = {s.name: s for s in diag.status}
    assert (by_name["filter"].level, by_name["filter"].message) == (1, "solved")
    assert {kv.key: kv.value for kv in by_name["filter"].values} == {"u_des_x": "0.5", "u_x": "0.25"}
    assert [float(by_name[n].values[0].value) for n in CONSTRAINT_NAMES] == [0.5 + i for i in
                                                                           range(len(CONSTRAINT_NAMES))]
    log_time, raw = client.messages[ids[2]][0]
    run = decode("diagnostic_msgs/msg/DiagnosticArray", raw)
    assert [(s.name, s.message, [(kv.key, kv.value) for kv in s.values]) for s in run.status] == \
        [(topics.RUN_STATUS_NAME, topics.RUN_RUNNING, [("commands", "7")])]
    assert log_time == 5_000_000_000


@pytest.mark.dds
def test_sim_time_sends_clock_as_the_server_time(run_publisher: dict[str, Any],
                                                  servers: Callable[..., Server]) -> None:
    server = servers("--port", "0", "--sim-time", "--topics", "/clock")
    ws = WsClient(server.port(), [SDK_SUBPROTOCOL])
    client = FoxgloveClient(ws)
    times: list[int] = []
    handle = client.handle

    def handle_time(frame: str | bytes) -> None:
        if isinstance(frame, bytes) and frame[0] == OP_TIME:
            times.append(struct.unpack_from("<Q", frame, 1)[0])
        handle(frame)

    client.handle = handle_time  # type: ignore[method-assign]
    try:
        client.pump_until(lambda: client.server_info is not None, "serverInfo")
        assert "time" in client.server_info["capabilities"]  # type: ignore[index]
        client.pump_until(lambda: len(times) >= 3, "3 time messages")
    finally:
        ws.close()
    assert all(t > CLOCK_START_NS for t in times) and times == sorted(times)
    assert all((t - CLOCK_START_NS) % 10_000_000 == 0 for t in times), "the /clock values, as published"
    assert server.stop(signal.SIGTERM) == 0, "".join(server.stderr)


@pytest.mark.dds
def test_ctrl_c_and_sigterm_exit_0_and_free_the_port(servers: Callable[..., Server]) -> None:
    for sig in (signal.SIGINT, signal.SIGTERM):
        server = servers("--port", "0")
        port = server.port()
        assert server.stop(sig) == 0, "".join(server.stderr)
        assert "Traceback" not in "".join(server.stderr)
        with socket.socket() as sock:  # nothing (no orphan) holds the port any more
            sock.bind(("127.0.0.1", port))


def close_reply(ws: WsClient) -> bytes:
    """The payload of the next Close frame from the server (frames before it are skipped); ConnectionError if
    the connection ends without one (what a browser reports as code 1006)."""
    while True:
        b0, payload = ws.frame()
        if b0 & 0x0F == 0x8:
            return payload


@pytest.mark.dds
def test_the_server_completes_the_closing_handshake(servers: Callable[..., Server]) -> None:
    """A client's Close (1000) gets a Close with its code back before the connection ends, on the port and on
    the legacy port (foxglove-sdk alone drops the connection: code 1006); clients still connected when the
    server stops get 1001 (going away)."""
    server = servers("--port", "0", "--legacy-port", "0")
    ports = {SDK_SUBPROTOCOL: server.port(),
             LEGACY_SUBPROTOCOL: server.port("foxglove server (foxglove.websocket.v1 relay) listening on ")}
    for protocol, port in ports.items():
        for code in (1000, 4001):
            ws = WsClient(port, [protocol])
            try:
                assert ws.status == 101 and ws.subprotocol == protocol
                client = FoxgloveClient(ws)
                client.pump_until(lambda c=client: c.server_info is not None, "serverInfo")
                ws.send(0x8, struct.pack(">H", code))
                assert close_reply(ws)[:2] == struct.pack(">H", code), protocol
                assert ws.sock.recv(1) == b""  # then the server closes the connection
            finally:
                ws.sock.close()
    connected = [WsClient(port, [protocol]) for protocol, port in ports.items()]
    try:
        for ws in connected:
            client = FoxgloveClient(ws)
            client.pump_until(lambda c=client: c.server_info is not None, "serverInfo")
        assert server.stop(signal.SIGINT) == 0, "".join(server.stderr)
        for ws in connected:
            assert close_reply(ws)[:2] in (struct.pack(">H", 1001), b"")  # going away (the SDK's: no code)
    finally:
        for ws in connected:
            ws.sock.close()


def test_message_definitions_are_found_without_ament_prefix_path() -> None:
    """A plain venv sets no AMENT_PREFIX_PATH: the bridge finds the definitions of every run topic's type where
    the pip wheels put them (sys.prefix), the same as with the variable set."""
    from rta_attitude.ros.foxglove_bridge import MessageDefinitionCache

    types = sorted(set(RUN_TOPICS.values()))
    code = ("import json, os, sys; from rta_attitude.ros.foxglove_bridge import MessageDefinitionCache; "
            "c = MessageDefinitionCache(); "
            f"print(json.dumps({{'env': 'AMENT_PREFIX_PATH' in os.environ, 'defs': {{t: c.complete_definition(t) "
            f"for t in {types!r}}}}}))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT,
                          env=plain_venv_env())
    assert proc.returncode == 0, proc.stderr
    found = json.loads(proc.stdout)
    assert found["env"] is False
    with_variable = MessageDefinitionCache()
    assert found["defs"] == {t: list(with_variable.complete_definition(t)) for t in types}
    assert all(encoding == "ros2msg" for encoding, _ in found["defs"].values())


@pytest.mark.dds
def test_a_plain_venv_server_advertises_the_run_topics(run_publisher: dict[str, Any],
                                                       servers: Callable[..., Server]) -> None:
    server = servers("--port", "0", "--topics", "/rta/.*", "--rescan-period", "0.3", env=plain_venv_env())
    ws = WsClient(server.port(), [SDK_SUBPROTOCOL])
    client = FoxgloveClient(ws)
    wanted = {f"/rta/{topics.STATE}": "sensor_msgs/msg/JointState",
              f"/rta/{topics.FILTER_STATUS}": "diagnostic_msgs/msg/DiagnosticArray"}
    try:
        client.pump_until(lambda: all(client.channel(t) for t in wanted), "advertise of state and filter_status")
    finally:
        ws.close()
    for topic, type_name in wanted.items():
        chan = client.channel(topic)
        assert chan is not None and (chan["schemaName"], chan["schemaEncoding"]) == (type_name, "ros2msg")
        assert get_types_from_msg(chan["schema"], type_name)[type_name][1] == TYPESTORE.fielddefs[type_name][1]
    assert not any("cannot bridge" in line for line in server.stderr), server.stderr


@pytest.mark.dds
def test_port_in_use_is_one_error_line_and_exit_1(servers: Callable[..., Server]) -> None:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen()
        server = servers("--port", str(sock.getsockname()[1]))
        rc = server.popen.wait(timeout=DEADLINE_S)
        for t in server.threads:
            t.join(timeout=DEADLINE_S)
    err = [line for line in server.stderr if line.strip()]
    assert rc == 1
    assert len(err) == 1 and err[0].startswith("ERROR: port ") and "in use" in err[0], err


# ----------------------------------------------------------------------------- layout

LAYOUT: dict[str, Any] = json.loads(LAYOUT_FILE.read_text())
KNOWN_PANEL_TYPES = {"3D", "Plot", "StateTransitions", "RawMessages", "DiagnosticSummary",
                     "DiagnosticStatusPanel", "Tab"}
PLOTTABLE = {"bool", "float32", "float64", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32",
             "uint64", "string", "byte", "char"}
MODIFIERS = {"abs": abs, "sqrt": math.sqrt}
"""Message path math modifiers that both apps' time-series plots apply, as functions of the value (Lichtblick's
plots have no rad2deg: it is ignored there without a word, so the layout must not use it)."""
_TOPIC = re.compile(r"/[A-Za-z0-9_/]*[A-Za-z0-9_]")
_ELEMENT = re.compile(r'\.([A-Za-z0-9_]+)(\[(\d+|:)\])?((?:\{[A-Za-z0-9_]+==(?:"[^"]*"|-?\d+)\})*)')
_FILTER = re.compile(r'\{([A-Za-z0-9_]+)==("[^"]*"|-?\d+)\}')
_MODIFIER = re.compile(r"\.@([a-z0-9]+)$")
_NUMBER = re.compile(r"-?\d+(\.\d+)?")
H_PATH = re.compile(r'/rta/filter_status\.status\[:\]\{name=="([a-z0-9_]+)"\}\.values\[:\]\{key=="h"\}\.value')
STATE_PATH = re.compile(r"/rta/state\.position\[(\d+)\]")


def split_modifier(path: str) -> tuple[str, str | None]:
    """(the path without a trailing `.@modifier`, the modifier or None)."""
    m = _MODIFIER.search(path)
    return (path[:m.start()], m.group(1)) if m else (path, None)


def mosaic_leaves(node: Any) -> list[str]:
    if isinstance(node, str):
        return [node]
    assert set(node) <= {"direction", "first", "second", "splitPercentage"}, node
    assert node["direction"] in ("row", "column")
    assert 0 <= node.get("splitPercentage", 50) <= 100
    return mosaic_leaves(node["first"]) + mosaic_leaves(node["second"])


def all_panel_ids(layout: dict[str, Any] = LAYOUT) -> list[str]:
    ids = mosaic_leaves(layout["layout"])
    for panel_id in list(ids):
        if panel_id.startswith("Tab!"):
            for tab in layout["configById"][panel_id]["tabs"]:
                ids += mosaic_leaves(tab["layout"])
    return ids


def _field(type_name: str, name: str) -> tuple[str, str, bool]:
    """(kind 'msg'|'prim', type, is_array) of a field, from rosbags' Jazzy definitions."""
    fields = dict(TYPESTORE.fielddefs[type_name][1])
    assert name in fields, f"{type_name} has no field {name!r}"
    nodetype, detail = fields[name]
    is_array = nodetype in (Nodetype.ARRAY, Nodetype.SEQUENCE)
    if is_array:
        nodetype, detail = detail[0]
    if nodetype == Nodetype.NAME:
        return "msg", detail, is_array
    return "prim", detail[0], is_array


def resolve(path: str) -> tuple[str, list[tuple[str, str, str]]]:
    """Type-check a message path (a trailing math modifier aside); returns (leaf primitive type, [(type, field,
    value) of each filter])."""
    path, modifier = split_modifier(path)
    assert modifier is None or modifier in MODIFIERS, f"{path}: unknown modifier @{modifier}"
    m = _TOPIC.match(path)
    assert m, path
    topic = m.group(0)
    assert topic in RUN_TOPICS, f"{path}: {topic} is not a topic of the run"
    kind, type_name, is_array, pos, filters = "msg", RUN_TOPICS[topic], False, m.end(), []
    while pos < len(path):
        e = _ELEMENT.match(path, pos)
        assert e, f"cannot parse {path!r} at {path[pos:]!r}"
        assert kind == "msg" and not is_array, f"{path}: .{e.group(1)} on {type_name}"
        kind, type_name, is_array = _field(type_name, e.group(1))
        if e.group(2):
            assert is_array, f"{path}: slice on a non-array {e.group(1)}"
            is_array = False
        for key, value in _FILTER.findall(e.group(4)):
            assert kind == "msg", f"{path}: filter on {type_name}"
            fkind, ftype, farray = _field(type_name, key)
            assert fkind == "prim" and not farray, f"{path}: filter on {key}"
            assert (ftype == "string") == value.startswith('"'), f"{path}: {key} is {ftype}"
            filters.append((type_name, key, value.strip('"')))
        pos = e.end()
    assert kind == "prim" and not is_array, f"{path}: leaf is {type_name}"
    return type_name, filters


def _paths(layout: dict[str, Any] = LAYOUT) -> list[tuple[str, str]]:
    return [(pid, p["value"]) for pid, cfg in layout["configById"].items() for p in cfg.get("paths", [])]


def test_shipped_layout_is_the_generators_output_for_the_default_config() -> None:
    assert LAYOUT_FILE.read_text() == layout_module.layout_json(CFG), \
        "regenerate it: python -m rta_attitude.recording.layout config/foxglove_layout.json"


def test_layout_is_layout_data_with_every_panel_placed_once_and_configured() -> None:
    assert set(LAYOUT) == {"configById", "layout", "globalVariables", "userNodes", "playbackConfig"}
    ids = all_panel_ids()
    assert len(ids) == len(set(ids)), "a panel is placed twice"
    assert set(ids) == set(LAYOUT["configById"]), "every placed panel has a config and every config a place"
    for panel_id in ids:
        kind, _, suffix = panel_id.partition("!")
        assert kind in KNOWN_PANEL_TYPES and suffix, panel_id
        assert isinstance(LAYOUT["configById"][panel_id], dict) and LAYOUT["configById"][panel_id]
    for panel_id, cfg in LAYOUT["configById"].items():
        for p in cfg.get("paths", []):
            assert p["timestampMethod"] in ("receiveTime", "headerStamp") and isinstance(p["enabled"], bool)
        titles = {cfg.get(k) for k in layout_module.TITLE_KEYS}
        assert len(titles) == 1, f"{panel_id}: the two apps' titles differ: {titles}"


def test_every_topic_the_layout_names_is_published_by_the_run() -> None:
    named = [cfg[k] for cfg in LAYOUT["configById"].values() for k in ("topicToRender", "topicPath") if k in cfg]
    named += [t for cfg in LAYOUT["configById"].values() for t in cfg.get("topics", {})]
    named += [_TOPIC.match(p).group(0) for _, p in _paths() if _TOPIC.match(p)]  # type: ignore[union-attr]
    assert named
    assert sorted(set(named) - set(RUN_TOPICS)) == []


@pytest.mark.parametrize(("panel_id", "path"), _paths())
def test_every_field_path_exists_in_its_message_type(panel_id: str, path: str) -> None:
    if _NUMBER.fullmatch(path):
        return  # a number is a reference line (the zero and limit lines of the margin plots)
    leaf, filters = resolve(path)
    assert leaf in PLOTTABLE, f"{panel_id}: {path} ends on {leaf}"
    entry = None
    for type_name, key, value in filters:  # filter_status: entry names and keys the filter writes
        if (type_name, key) == ("diagnostic_msgs/msg/DiagnosticStatus", "name"):
            assert value in (topics.QP_STATUS_NAME, *CONSTRAINT_NAMES), path
            entry = value
        if (type_name, key) == ("diagnostic_msgs/msg/KeyValue", "key"):
            keys = topics.QP_KEYS if entry == topics.QP_STATUS_NAME else topics.CONSTRAINT_KEYS
            assert value in keys, f"{path}: {value!r} is not a key of the {entry!r} entry"


def margin_series(layout: dict[str, Any]) -> dict[str, tuple[str, str | None, list[float]]]:
    """{constraint: (panel, modifier, reference lines of its panel)} of every margin series of a layout: h of a
    filter_status entry, or a body rate / wheel speed of `state` (named by STATE_NAMES: omega_x ... psi_z)."""
    out: dict[str, tuple[str, str | None, list[float]]] = {}
    for panel_id, cfg in layout["configById"].items():
        values = [p["value"] for p in cfg.get("paths", [])]
        lines = sorted(float(v) for v in values if _NUMBER.fullmatch(v))
        for v in values:
            path, modifier = split_modifier(v)
            h, state = H_PATH.fullmatch(path), STATE_PATH.fullmatch(path)
            if h or state:
                name = h.group(1) if h else STATE_NAMES[int(state.group(1))]  # type: ignore[union-attr]
                assert name not in out, f"{name} is plotted twice"
                out[name] = (panel_id, modifier, lines)
    return out


def test_every_margin_is_plotted_in_its_unit_with_its_limit_lines_one_unit_to_a_plot() -> None:
    series = margin_series(LAYOUT)
    assert sorted(series) == sorted(CONSTRAINT_NAMES)
    L = CFG.limits
    unit = {c.name: "rad" for c in CFG.pointing} | {"temperature": "K", "battery": "J"}
    unit |= {f"omega_{a}": "rad/s" for a in "xyz"} | {f"psi_{a}": "rad/s" for a in "xyz"}
    for name, (_, modifier, lines) in series.items():
        if name.startswith("omega_"):  # the rate itself in rad/s between -omega_max and +omega_max
            assert modifier is None and lines == pytest.approx([-L.omega_max_rad_s, L.omega_max_rad_s], rel=1e-3)
        elif name.startswith("psi_"):  # the wheel speed in rad/s between -psi_max and +psi_max
            assert modifier is None and lines == pytest.approx([-L.psi_max_rad_s, L.psi_max_rad_s], abs=1e-4)
        else:  # h with its zero line: the cones' in deg, temperature's in K, battery's in J
            assert modifier is None and lines == [0.0], name
    panels = {p for p, _, _ in series.values()}
    for panel in panels:
        units = {unit[n] for n, (p, _, _) in series.items() if p == panel}
        assert len(units) == 1, f"{panel} mixes units {units}"
        title = LAYOUT["configById"][panel]["foxglovePanelTitle"]
        assert f"[{units.pop()}]" in title, title
    values = [p["value"] for p in LAYOUT["configById"][layout_module.TORQUE_PLOT]["paths"]]
    assert values == [f"/rta/{t}.vector.{axis}" for axis in "xyz" for t in ("torque_des", "torque_cmd")]
    state_paths = [p for _, p in _paths() if p.startswith("/rta/filter_status.status[:]{name==\"filter\"}")]
    assert state_paths, "the filter status is shown"


def test_a_third_cone_gets_its_own_margin_series_and_status_row() -> None:
    import dataclasses

    from rta_attitude.config.schema import PointingConstraint

    cone = PointingConstraint(name="star_tracker", kind="keep_out", boresight_body=(0.0, 0.0, -1.0), target="earth",
                              half_angle_rad=math.radians(30), gains=CFG.pointing[0].gains)
    levels = CFG.filter.priorities
    cfg = dataclasses.replace(CFG, pointing=(*CFG.pointing, cone), filter=dataclasses.replace(
        CFG.filter, priorities=levels[:1] and (levels[0] + ("star_tracker",), *levels[1:])))
    layout = json.loads(layout_module.layout_json(cfg))
    series = margin_series(layout)
    assert sorted(series) == sorted(cfg.constraint_names)
    assert series["star_tracker"][:2] == (layout_module.POINTING_PLOT, None)
    labels = [p["label"] for p in layout["configById"][layout_module.POINTING_PLOT]["paths"]]
    assert labels[2].startswith("star_tracker (>= 30 deg, Earth)")
    status = [p["value"] for p in layout["configById"]["StateTransitions!filter_status"]["paths"]]
    assert '/rta/filter_status.status[:]{name=="star_tracker"}.message' in status
    for _, path in _paths(layout):
        if not _NUMBER.fullmatch(path):
            resolve(path)
    assert set(all_panel_ids(layout)) == set(layout["configById"])
    other = json.loads(layout_module.layout_json(cfg, "/sat2"))
    assert all(p.startswith("/sat2/") for _, p in _paths(other) if not _NUMBER.fullmatch(p))


def _evaluate(path: str, msg: Any) -> list[Any]:
    """A message path on a decoded message, as the apps evaluate it: slices and filters fan out to a list; a
    trailing math modifier applies to each number (the apps read numeric strings as numbers)."""
    path, modifier = split_modifier(path)
    m = _TOPIC.match(path)
    assert m, path
    items, pos = [msg], m.end()
    while pos < len(path):
        e = _ELEMENT.match(path, pos)
        assert e, path
        items = [getattr(item, e.group(1)) for item in items]
        if e.group(2):
            index = e.group(3)
            items = [x for item in items for x in (list(item) if index == ":" else [list(item)[int(index)]])]
        for key, value in _FILTER.findall(e.group(4)):
            want: Any = value.strip('"') if value.startswith('"') else int(value)
            items = [item for item in items if getattr(item, key) == want]
        pos = e.end()
    return items if modifier is None else [MODIFIERS[modifier](float(v)) for v in items]


def test_every_filter_status_and_state_path_reads_one_value_of_a_real_message() -> None:
    """The layout's filter_status paths on a message the filter node's builder makes (the filter's answer at
    paper_example's initial state, serialized by rclpy), and its state paths on the plant's state message (its
    CDR writer), decoded by rosbags: every path gives one value, each margin path exactly the h of its constraint
    (repr of the float64, which the apps read as that number; in deg for the cones), each state path its
    component."""
    import numpy as np
    from rclpy.serialization import serialize_message

    from rta_attitude.filter.asif import AsifFilter
    from rta_attitude.ros import convert

    filt = AsifFilter(CFG)
    x0 = np.asarray(CFG.scenario("paper_example").x0, dtype=float)
    x0[4:10] = [0.01, -0.005, 0.002, 120.0, -80.0, 5.0]
    res = filt.filter(x0, np.zeros(3))
    msg = decode("diagnostic_msgs/msg/DiagnosticArray",
                 bytes(serialize_message(convert.filter_status_msg(res, 42, filt.counters, "robust", ()))))
    state = decode("sensor_msgs/msg/JointState", convert.state_cdr(x0, 42))  # the bytes the plant publishes
    checked = 0
    for panel_id, path in _paths():
        if path.startswith("/rta/state."):
            values = _evaluate(path, state)
            i = int(STATE_PATH.fullmatch(split_modifier(path)[0]).group(1))  # type: ignore[union-attr]
            assert values == [x0[i]], path
            checked += 1
        if not path.startswith("/rta/filter_status."):
            continue
        values = _evaluate(path, msg)
        assert len(values) == 1, f"{panel_id}: {path} gives {values}"
        name = re.search(r'name=="([a-z_]+)"', path).group(1)  # type: ignore[union-attr]
        if H_PATH.fullmatch(split_modifier(path)[0]):
            h = res.h[list(res.names).index(name)]
            assert float(values[0]) == h, path
        checked += 1
    assert checked >= len(CONSTRAINT_NAMES)


@pytest.mark.parametrize("type_name", sorted(set(RUN_TOPICS.values())))
def test_schema_of_every_run_topic_is_its_jazzy_definition(type_name: str) -> None:
    """The ros2msg schema the server sends for each of the run's types, parsed by rosbags, gives rosbags' own
    Jazzy definitions of the type and of every nested type; header detection drives the log time."""
    from rta_attitude.ros.foxglove_bridge import MessageDefinitionCache

    cache = MessageDefinitionCache([Path(sys.prefix)])
    encoding, text = cache.complete_definition(type_name)
    assert encoding == "ros2msg"
    parsed = get_types_from_msg(text, type_name)
    for name, fields in parsed.items():
        assert fields[1] == TYPESTORE.fielddefs[name][1], name
    first = TYPESTORE.fielddefs[type_name][1][0][1]
    assert cache.starts_with_header(type_name) == (first == (Nodetype.NAME, "std_msgs/msg/Header"))


def test_log_time_is_the_leading_stamp_of_the_cdr() -> None:
    from rta_attitude.ros.foxglove_bridge import cdr_leading_time_ns

    t = TYPESTORE.types
    msg = t["geometry_msgs/msg/Vector3Stamped"](
        header=t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=12, nanosec=345), frame_id="b"),
        vector=t["geometry_msgs/msg/Vector3"](x=1.0, y=2.0, z=3.0))
    for little in (True, False):
        raw = bytes(TYPESTORE.serialize_cdr(msg, "geometry_msgs/msg/Vector3Stamped", little_endian=little))
        assert cdr_leading_time_ns(raw) == 12_000_000_345
    zero = raw[:4] + bytes(8) + raw[12:]
    assert cdr_leading_time_ns(zero) is None and cdr_leading_time_ns(zero, allow_zero=True) == 0
