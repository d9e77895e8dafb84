"""scene_node: the attitude scene as ROS topics a 3D panel draws (Foxglove, Lichtblick, RViz), off the
control path.

Two ways to run (the `scene` knob, topics.SCENE_MODES):

- hosted by the recorder (`recorder`, what the launch file and `rta-attitude launch` do when they record):
  a node in the recorder's process, fed the serialized `state` and `filter_status` the recorder receives
  (`take_state`, `take_status`), so the loop's messages are not delivered a second time; it publishes what
  it draws and the recorder writes it into the bag at once (complete: one transform and one marker array
  per state). Measured: a fifth process reading the loop's two messages a step cost the lockstep loop 1.25x
  on 2 cores, hosted it costs it nothing measurable (README, Performance);
- a process of its own (`node`: `ros2 run rta_attitude scene_node`, or a launch without a recorder): it
  reads `state` (what the filter sees; with sensor errors, the measured state) and, with RTA,
  `filter_status`, both best effort (topics.VIEW_QOS: no writer of the loop waits for a view; a view that
  falls behind or loses a sample under load skips states).

For every `scene_every`-th state (the steps k with k % scene_every == 0, by the state's stamp)
publishes, stamped like the state:

- `scene/transform` (geometry_msgs/TransformStamped, hill -> body, rotation = the state's q), which
  Foxglove's and Lichtblick's 3D panels read as a transform on any topic (no tf2_msgs wheel on PyPI);
- `scene/markers` (visualization_msgs/MarkerArray, frame hill; `convert.SceneBuilder`): the body and
  its axes, the panel normal, and for every configured pointing constraint its boresight (coloured by its
  margin: ok, within `scene_warn_deg`, violated; grey outside its windows) and its cone about its target,
  one arrow per distinct target, and a text (`scene_text`: lines of at most TEXT_LINE_CHARS) with the time,
  the filter's status, the constraints it intervenes for and each cone's angle against its limit.

The node (of its own) runs without use_sim_time (it draws by the states' stamps, and reading /clock would cost it a
message a step); a state older than the last one drawn (a replay that starts over) starts it over.

With RTA a state is drawn when its filter_status (same stamp) has come too, so the text belongs to the
state drawn; a state whose status never comes (a filter that died) is drawn without it once
PENDING_MAX later states are waiting. Every geometric fact comes from the core (`recording.scene`:
A(q), the targets' directions, the boresights, `ConstraintSet.angles` and `safety_values`); the constraints'
names come from the configuration (`Config.constraint_names`), so a node reads the filter_status of a
filter of the same configuration.

Bad input: a state that the fast CDR reader cannot read, with wrong names or non-finite values, is
counted (`state_rejected`) and not drawn; nothing of the loop depends on this node.
"""

from __future__ import annotations

import functools
import math
import struct
import textwrap
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from rta_attitude import topics
from rta_attitude.constraints import ConstraintSet
from rta_attitude.dynamics.state import STATE_NAMES, Q
from rta_attitude.recording.cdr import Cdr, CdrError, read_diagnostics, read_state
from rta_attitude.recording.scene import Scene, cone_text, scene_of_states
from rta_attitude.ros import convert, interface, spin
from rta_attitude.ros.spin import RtaNode

PENDING_MAX = 16
"""States (or statuses) kept waiting for their partner; beyond, the oldest state is drawn alone (a status lost
by the best-effort reader)."""
HOSTED_PENDING_MAX = 100_000
"""The same for a scene hosted by the recorder: nothing is lost there (reliable readers), but the recorder's
executor may take many states before their statuses."""
LEVELS = {"pass": 0, "solved": 1}
"""filter_status QP status -> text level (anything else, a fallback: 2)."""
TEXT_LINE_CHARS = 60
"""The scene text's longest line (longer ones are wrapped), so that it fits a 3D panel."""


_U32 = struct.Struct("<I")


def _cdr_name(name: str) -> bytes:
    return _U32.pack(len(name) + 1) + name.encode() + b"\x00"


_GAVE_WAY = _cdr_name("gave_way")


@functools.cache
def _entry_names(names: tuple[str, ...]) -> tuple[tuple[str, bytes], ...]:
    """Each constraint's name and its filter_status entry's name as CDR bytes."""
    return tuple((n, _cdr_name(topics.CONSTRAINT_STATUS_PREFIX + n)) for n in names)


def filter_summary(data: bytes, names: Sequence[str]) -> tuple[int, str, str, list[str]]:
    """(stamp [ns], message of the `filter` entry, gave_way, the constraints intervening) of a serialized
    filter_status (little-endian CDR, the layout of `convert.FilterStatusBuilder`) of the constraints `names`
    (`Config.constraint_names`), read without decoding its ~120 key-value pairs (a full read took ~0.1 ms, at
    every step): the `filter` entry's head, then its last key `gave_way`, then each constraint entry's name and
    message (`intervening`, `ok`, `violated`) in order. Raises CdrError on anything else (the caller then reads
    it with `read_diagnostics`)."""
    if len(data) < 8 or data[:2] != b"\x00\x01":
        raise CdrError("not little-endian CDR")
    c = Cdr(data)
    t_ns = c.header()
    c.u32()
    c.u8()
    if c.string() != topics.QP_STATUS_NAME:
        raise CdrError("the first entry is not the filter's")
    message = c.string()
    i = data.find(_GAVE_WAY, c.pos)
    if i < 0:
        raise CdrError("no gave_way key")
    c.pos = i + len(_GAVE_WAY)
    gave_way = c.string()
    intervening = []
    for name, pattern in _entry_names(tuple(names)):
        j = data.find(pattern, c.pos)
        if j < 0:
            raise CdrError(f"no {name} entry")
        c.pos = j + len(pattern)
        if c.string() == "intervening":
            intervening.append(name)
    return t_ns, message, gave_way, intervening


def summary_from_values(values: dict[str, dict[str, str]], names: Sequence[str]) -> tuple[str, str, list[str]]:
    """(message, gave_way, intervening) of a filter_status read by `recording.cdr.read_diagnostics`, of the
    constraints `names`."""
    qp = values.get(topics.QP_STATUS_NAME, {})
    status, fallback = qp.get(topics.KEY_STATUS, "?"), qp.get(topics.KEY_FALLBACK, topics.NO_FALLBACK)
    message = status + (f" ({fallback})" if fallback != topics.NO_FALLBACK else "")
    inter = [n for n in names
             if values.get(topics.CONSTRAINT_STATUS_PREFIX + n, {}).get(topics.KEY_INTERVENING) == "true"]
    return message, qp.get("gave_way", ""), inter


def filter_text(message: str, gave_way: str, intervening: Sequence[str]) -> tuple[str, int]:
    """(line, level) for the scene's text: the filter entry's message (`solved`, `fallback (prioritize)`),
    the level that gave way, the constraints the filter intervened for; level 0 pass, 1 solved, 2 else."""
    line = f"filter {message}" + (f", gave way: {gave_way}" if gave_way else "")
    if intervening:
        line += "\nintervening: " + ", ".join(intervening)
    return line, LEVELS.get(message.split(" ")[0], 2)


def wrap_lines(text: str, width: int = TEXT_LINE_CHARS) -> str:
    """text with every line longer than `width` broken at spaces (continuations indented two spaces; a word
    longer than a line is broken too)."""
    out: list[str] = []
    for line in text.split("\n"):
        out += textwrap.wrap(line, width, subsequent_indent="  ", break_on_hyphens=False) or [""]
    return "\n".join(out)


def scene_text(t_s: float, status: str, sc: Scene, k: int = 0) -> str:
    """The scene's text at sample k of `sc`: the time and the filter's status lines (`filter_text`), then
    one line per pointing constraint (`recording.scene.cone_text`), no line longer than TEXT_LINE_CHARS."""
    return wrap_lines("\n".join([f"t = {t_s:.0f} s   {status}", *(cone_text(c, k) for c in sc.cones)]))


class SceneNode(RtaNode):
    """The attitude scene; see the module docstring.

    Args:
        hosted: hosted in another node's process (the recorder's, topics.SCENE_RECORDER): no subscriptions of
            its own; the host feeds it the serialized messages it receives (`take_state`, `take_status`), and
            `hosted(t_ns, transform, markers)` gets what it draws (the recorder writes it into the bag).
        **kwargs: passed to RtaNode (context, namespace, parameter_overrides, ...).
    """

    def __init__(self, hosted: Callable[[int, bytes, bytes], None] | None = None, **kwargs: Any) -> None:
        super().__init__(topics.SCENE, **kwargs)
        self.sink = hosted
        self.pending_max = PENDING_MAX if hosted is None else HOSTED_PENDING_MAX
        self.every: int = self.knobs["scene_every"]
        self.dt_ns = round(self.cfg.filter.sample_time_s * convert.NS_PER_S)
        self.constraints = ConstraintSet(self.cfg)
        self.names = self.cfg.constraint_names
        self.builder = convert.SceneBuilder(self.cfg.pointing, math.radians(self.knobs["scene_warn_deg"]))
        self.counts.update(state_rejected=0, drawn=0, drawn_without_status=0)
        # compiled kernels loaded (compiled on a cold cache, ~20-40 s) before any reader or writer exists: the
        # plant starts stepping once this node reads `state`, so it must be able to draw by then (a fresh
        # clone's CI run found a scene that subscribed first, compiled while the 300-step run went by, and
        # drew after the recorder had closed the bag)
        scene_of_states([0.0], self.scenario.x0, self.cfg, self.constraints)
        self.outs = {}
        for topic in topics.SCENE_TOPICS:
            spec = topics.TOPICS[topic]
            pub = self.create_publisher(interface.msg_class(spec.type_name), spec.name, self.qos(topic))
            self.outs[topic] = self.gate(topic, pub)
        self.states: dict[int, np.ndarray] = {}
        self.statuses: dict[int, tuple[str, int]] = {}
        self.drawn_ns = -1
        source = topics.STATE
        if hosted is None:
            # a process of its own reads the state only once its readers (the recorder) have matched what it
            # publishes: the plant waits for this node to read the state, so the run cannot outpace a
            # discovery that is slow under load (a run of 300 steps took 3 s, and every drawing waited in
            # the gates until the bag was closed)
            self._subscribe_timer = self.wall_timer(spin.GATE_POLL_S, self._subscribe_when_matched)
        self.get_logger().info(f"drawing {self.resolve_topic_name(source)} every {self.every} step(s)"
                               + (" with the filter's status" if self.rta else "")
                               + (", hosted by the recorder" if hosted is not None else ""))

    def _wanted(self, t_ns: int) -> bool:
        return round((t_ns - self.epoch_ns) / self.dt_ns) % self.every == 0

    def take_state(self, data: bytes) -> None:
        """A serialized `state` (its subscription's callback, or the host's call)."""
        try:
            t_ns, names, x = read_state(Cdr(data))
            if names != STATE_NAMES or x.shape != (len(STATE_NAMES),) or not np.all(np.isfinite(x)):
                raise CdrError(f"not a usable state ({len(names)} names, {x.size} values)")
        except (CdrError, ValueError, IndexError) as exc:
            self.faults.fault("state_rejected", f"state not drawn: {exc}")
            return
        self.faults.clear("state_rejected")
        if t_ns <= self.drawn_ns:
            if t_ns < self.drawn_ns:  # time went back (a replay started over): start over too
                self.on_clock_jump()
            else:
                return
        if not self._wanted(t_ns):
            return
        if not self.rta:
            self._draw(t_ns, x, None)
        elif t_ns in self.statuses:
            self._draw(t_ns, x, self.statuses.pop(t_ns))
        else:
            self.states[t_ns] = x
            if len(self.states) > self.pending_max:
                oldest = min(self.states)
                self.counts["drawn_without_status"] += 1
                self._draw(oldest, self.states.pop(oldest), None)

    def take_status(self, data: bytes) -> None:
        """A serialized `filter_status` (its subscription's callback, or the host's call)."""
        try:
            try:
                t_ns, *summary = filter_summary(data, self.names)
            except (CdrError, ValueError, IndexError, UnicodeDecodeError, struct.error):
                t_ns, values = read_diagnostics(Cdr(data))
                summary = list(summary_from_values(values, self.names))
        except (CdrError, ValueError, IndexError, UnicodeDecodeError, struct.error):
            return  # the text then says the status is missing; the filter's own checks count bad statuses
        if t_ns <= self.drawn_ns or not self._wanted(t_ns):
            return
        info = filter_text(*summary)
        if t_ns in self.states:
            self._draw(t_ns, self.states.pop(t_ns), info)
        else:
            self.statuses[t_ns] = info
            while len(self.statuses) > self.pending_max:
                self.statuses.pop(min(self.statuses))

    def _subscribe_when_matched(self) -> None:
        if not all(gate.matched() for gate in self.outs.values()):
            return
        self.destroy_timer(self._subscribe_timer)
        view = interface.qos_profile(topics.VIEW_QOS)
        for topic, callback in ((topics.STATE, self.take_state), (topics.FILTER_STATUS, self.take_status)):
            if topic == topics.FILTER_STATUS and not self.rta:
                continue
            spec = topics.TOPICS[topic]
            self.create_subscription(interface.msg_class(spec.type_name), spec.name, callback, view, raw=True)

    def _draw(self, t_ns: int, x: np.ndarray, info: tuple[str, int] | None) -> None:
        t_s = self.sim_s(t_ns)
        sc = scene_of_states([t_s], x, self.cfg, self.constraints)
        if info is None:
            info = ("filter off (no RTA)", 0) if not self.rta else ("filter status missing", 2)
        line, level = info
        transform, markers = self.builder.build(x[Q], sc, 0, t_ns, scene_text(t_s, line, sc), level)
        self.outs[topics.SCENE_TRANSFORM].publish(transform)
        self.outs[topics.SCENE_MARKERS].publish(markers)
        if self.sink is not None:
            self.sink(t_ns, transform, markers)
        self.counts["drawn"] += 1
        self.drawn_ns = t_ns
        for pending in (self.states, self.statuses):
            for old in [s for s in pending if s <= t_ns]:
                del pending[old]

    def close(self) -> None:
        """Log as every node does, and the CPU time of its process (hosted: the recorder's too)."""
        self.get_logger().info(f"process CPU time {time.process_time():.2f} s; {self.counts['drawn']} states drawn")
        super().close()

    def on_clock_jump(self) -> None:
        self.drawn_ns = -1
        self.states.clear()
        self.statuses.clear()


def main(args: Sequence[str] | None = None) -> None:
    """Console script `scene_node` (`ros2 run rta_attitude scene_node --ros-args ...`)."""
    spin.main(SceneNode, args, topics.NODE_NAMES[topics.SCENE])


if __name__ == "__main__":
    main()
