"""MCAP bags written and read the way rosbag2's MCAP storage plugin (ROS 2 Jazzy) does, without ROS.

Layout of a file written by `BagWriter` (checked against rosbag2_storage_mcap/src/mcap_storage.cpp,
rosbag2_cpp's local_message_definition_source.cpp and rosbag2_storage's qos.cpp / yaml.hpp):

- MCAP header profile `ros2`; chunked, zstd (else lz4, else none), message indexes and a summary;
- one schema per type: name `pkg/msg/Type`, encoding `ros2msg`, data = the type's .msg file text
  and, for each nested type not yet written (depth first, sorted per level), `\\n`, a line of 80
  `=`, `MSG: pkg/Type` and that type's .msg text (`message_definition`);
- one channel per topic: message encoding `cdr`, metadata `offered_qos_profiles` (YAML as yaml-cpp
  dumps it, metadata version 9 enum names) and `topic_type_hash` (`RIHS01_...`, `type_hash`);
- messages: raw CDR, log_time / publish_time in nanoseconds (the message's time, e.g. sim time);
- at close, a metadata record `rosbag2` with `serialized_metadata` = the rosbag2 BagMetadata YAML
  (version 9), from which rosbag2's reader takes the metadata version and ROS distro.

A lone `.mcap` opens in `ros2 bag info/play`, Foxglove, PlotJuggler and `rosbags` (its Reader and
AnyReader take the file path). `write_metadata_yaml` adds the `metadata.yaml` of a rosbag2 bag
directory for tools that want one. Nothing here imports rclpy.
"""

from __future__ import annotations

import datetime as dt
import json
import os
import re
import struct
import sys
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import IO, Any, Self

import yaml
from mcap.exceptions import EndOfFile, McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer
from mcap_ros2._dynamic import serialize_dynamic
from mcap_ros2.decoder import DecoderFactory

from rta_attitude.errors import BagError

MAGIC = b"\x89MCAP0\r\n"
PROFILE = "ros2"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"
METADATA_VERSION = 9
"""rosbag2 BagMetadata version written (Jazzy: QoS enums as names)."""
DEFAULT_CHUNK_SIZE = 256 * 1024
"""Bytes of uncompressed records per chunk: a killed writer loses at most this much."""
LIBRARY = f"rta_attitude.recording.bag; {LIBRARY_IDENTIFIER}"
_SEPARATOR = "=" * 80
_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")  # rosbag2's regex
_PRIMITIVES = frozenset(
    {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16"}
    | {"int32", "uint32", "int64", "uint64", "string", "wstring"}
)
DURATION_INFINITE = (9223372036, 854775807)
"""RMW_DURATION_INFINITE as (sec, nsec), for `Qos` durations."""
_QOS_NAMES = {
    "history": ("keep_last", "keep_all", "system_default", "unknown"),
    "reliability": ("reliable", "best_effort", "system_default", "best_available", "unknown"),
    "durability": ("volatile", "transient_local", "system_default", "best_available", "unknown"),
    "liveliness": ("automatic", "manual_by_topic", "system_default", "best_available", "unknown"),
}


# ----------------------------------------------------------------------------- definitions


def _split_type(type_name: str) -> tuple[str, str]:
    """`pkg/msg/Type` or `pkg/Type` -> (pkg, Type); BagError otherwise."""
    parts = type_name.split("/")
    shape_ok = (len(parts) == 3 and parts[1] == "msg") or len(parts) == 2
    if shape_ok and all(re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", p) for p in parts):
        return parts[0], parts[-1]
    raise BagError(f"{type_name!r}: not a message type name like 'pkg/msg/Type'")


def _share_dirs() -> list[Path]:
    """Share directories searched for interface files: AMENT_PREFIX_PATH, then sys.prefix."""
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    return [Path(p) / "share" for p in [*prefixes, sys.prefix]]


def _interface_file(type_name: str, suffix: str) -> Path | None:
    pkg, name = _split_type(type_name)
    for share in _share_dirs():
        path = share / pkg / "msg" / f"{name}{suffix}"
        if path.is_file():
            return path
    return None


def _msg_text(type_name: str) -> str:
    path = _interface_file(type_name, ".msg")
    if path is None:
        dirs = ", ".join(str(d) for d in _share_dirs())
        raise BagError(f"{type_name}: no .msg file found under {dirs}")
    return path.read_text(encoding="utf-8")


def message_definition(type_name: str) -> str:
    """Full rosbag2 `ros2msg` text of a type, e.g. `"sensor_msgs/msg/JointState"`.

    Same algorithm as rosbag2_cpp's LocalMessageDefinitionSource: the .msg text, then for each
    dependency (sorted, depth first, each type once) `\\n` + 80 `=` + `\\nMSG: pkg/Type\\n` + text.
    """
    seen: set[str] = set()

    def text_of(name: str) -> str:
        pkg, _ = _split_type(name)
        text = _msg_text(name)
        deps = set()
        for match in _FIELD_TYPE.finditer(text):
            dep = match.group(1)
            if dep not in _PRIMITIVES:
                deps.add(dep if "/" in dep else f"{pkg}/{dep}")
        for dep in sorted(deps):
            if dep not in seen:
                seen.add(dep)
                text += f"\n{_SEPARATOR}\nMSG: {dep}\n{text_of(dep)}"
        return text

    return text_of(type_name)


def type_hash(type_name: str) -> str:
    """RIHS01 type hash from the installed type-description JSON ("" if there is none)."""
    pkg, name = _split_type(type_name)
    path = _interface_file(type_name, ".json")
    if path is None:
        return ""
    try:
        hashes = json.loads(path.read_text(encoding="utf-8")).get("type_hashes", [])
    except (OSError, ValueError):
        return ""
    full = f"{pkg}/msg/{name}"
    return next((h["hash_string"] for h in hashes if h.get("type_name") == full), "")


@dataclass(frozen=True)
class Qos:
    """One offered QoS profile as rosbag2 records it; durations are (sec, nsec), (0, 0) = default.

    Defaults are rclpy's default publisher profile (keep_last 10, reliable, volatile).
    """

    history: str = "keep_last"
    depth: int = 10
    reliability: str = "reliable"
    durability: str = "volatile"
    deadline: tuple[int, int] = (0, 0)
    lifespan: tuple[int, int] = (0, 0)
    liveliness: str = "system_default"
    liveliness_lease_duration: tuple[int, int] = (0, 0)
    avoid_ros_namespace_conventions: bool = False

    def __post_init__(self) -> None:
        for key, allowed in _QOS_NAMES.items():
            if getattr(self, key) not in allowed:
                raise BagError(f"QoS {key}={getattr(self, key)!r}: expected one of {allowed}")

    def as_dict(self) -> dict[str, Any]:
        """rosbag2 (metadata v9) mapping, keys in rosbag2's order."""
        d = asdict(self)
        for key in ("deadline", "lifespan", "liveliness_lease_duration"):
            d[key] = {"sec": d[key][0], "nsec": d[key][1]}
        return d


def offered_qos_yaml(profiles: Sequence[Qos]) -> str:
    """The channel metadata string, formatted as rosbag2's YAML::Dump (yaml-cpp) writes it."""
    if not profiles:
        return "[]"
    lines = []
    for qos in profiles:
        for i, (key, value) in enumerate(qos.as_dict().items()):
            lead = "- " if i == 0 else "  "
            if isinstance(value, dict):
                lines += [f"{lead}{key}:", f"    sec: {value['sec']}", f"    nsec: {value['nsec']}"]
            else:
                text = str(value).lower() if isinstance(value, bool) else value
                lines.append(f"{lead}{key}: {text}")
    return "\n".join(lines)


# ----------------------------------------------------------------------------- writing


class _Sink:
    """Unbuffered file sink: each batch of records the MCAP writer emits reaches the OS at once."""

    def __init__(self, file: IO[bytes]) -> None:
        self._file = file

    def write(self, data: bytes) -> int:
        view = memoryview(data)
        while view:
            view = view[self._file.write(view) or 0 :]
        return len(data)

    def tell(self) -> int:
        return self._file.tell()


class _Fields:
    """Attribute view of a message (rclpy object, namespace or mapping) for mcap_ros2's encoder."""

    __slots__ = ("_obj",)

    def __init__(self, obj: Any) -> None:
        self._obj = obj

    def __getattr__(self, name: str) -> Any:
        obj = self._obj
        return _plain(obj.get(name) if isinstance(obj, Mapping) else getattr(obj, name, None))


class _Byte(bytes):
    """One-byte `bytes` (rclpy's `byte` field) that the encoder may also read as an int."""

    def __int__(self) -> int:
        return self[0]


class _Char(str):
    """One-character `str` (rclpy's `char` field) that the encoder may also read as an int."""

    __slots__ = ()

    def __int__(self) -> int:
        return ord(self)


def _plain(value: Any) -> Any:
    """numpy, array.array, tuple -> list; nested messages -> `_Fields`; byte, char -> int-able."""
    if isinstance(value, bytes) and len(value) == 1:
        return _Byte(value)
    if isinstance(value, str) and len(value) == 1:
        return _Char(value)
    if value is None or isinstance(value, (bool, int, float, str, bytes)):
        return value
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return _Fields(value)


@dataclass
class _Topic:
    channel_id: int
    type_name: str
    qos: list[Qos]
    hash: str
    count: int = 0


def _compression(name: str) -> CompressionType:
    if name == "auto":
        for module, kind in (("zstandard", "zstd"), ("lz4.frame", "lz4")):
            try:
                __import__(module)
            except ImportError:
                continue
            return _compression(kind)
        return CompressionType.NONE
    kinds = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
    if name not in kinds:
        raise BagError(f"compression {name!r}: expected one of auto, zstd, lz4, none")
    return kinds[name]


def default_bag_name(now: dt.datetime | None = None) -> str:
    """A unique, time-stamped bag name as rosbag2 makes them (`rosbag2_2026_11_23-21_05_07`), with our
    prefix and the MCAP suffix: `rta_attitude_2026_11_23-21_05_07.mcap` (local time)."""
    return f"rta_attitude_{(now or dt.datetime.now()).strftime('%Y_%m_%d-%H_%M_%S')}.mcap"


class BagWriter:
    """Write a rosbag2-convention MCAP file; a context manager, `close()` is idempotent.

    Args:
        path: the .mcap file to create.
        overwrite: replace an existing file (otherwise an existing file is a BagError).
        chunk_size: uncompressed bytes per chunk [B]; a killed writer loses at most one chunk.
        compression: "auto" (zstd, else lz4, else none), "zstd", "lz4" or "none".
        ros_distro: recorded in the rosbag2 metadata record.
        overwrite_hint: how the caller's user asks for `overwrite` (named in the error when the file exists).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        overwrite: bool = False,
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        compression: str = "auto",
        ros_distro: str = "jazzy",
        overwrite_hint: str = "overwrite=True",
    ) -> None:
        self.path = Path(path)
        kind = _compression(compression)
        try:
            self._file = open(self.path, "wb" if overwrite else "xb", buffering=0)
        except FileExistsError:
            raise BagError(f"{self.path}: file exists (pass {overwrite_hint} to replace it)") from None
        except OSError as exc:
            raise BagError(f"{self.path}: cannot create ({exc.strerror})") from None
        sink: Any = _Sink(self._file)  # not an IO subclass, so mcap does not wrap it in a buffer
        self._writer = Writer(sink, chunk_size=chunk_size, compression=kind)
        self._writer.start(profile=PROFILE, library=LIBRARY)
        self._ros_distro = ros_distro
        self._schemas: dict[str, int] = {}
        self._topics: dict[str, _Topic] = {}
        self._encoders: dict[str, Callable[[Any], bytes]] = {}
        self._times: list[int] = []  # [min, max] log time [ns] once a message is written
        self._closed = False

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def add_topic(self, topic: str, type_name: str, qos: Qos | Sequence[Qos] | None = None) -> int:
        """Register `topic` of `type_name` (schema once per type, channel once); channel id.

        `qos`: the offered profile(s) recorded for `ros2 bag play`, default `Qos()`.
        """
        self._check_open()
        pkg, name = _split_type(type_name)
        type_name = f"{pkg}/msg/{name}"
        if topic in self._topics:
            if self._topics[topic].type_name != type_name:
                old = self._topics[topic].type_name
                raise BagError(f"{self.path}: topic {topic} already has type {old}, not {type_name}")
            return self._topics[topic].channel_id
        if type_name not in self._schemas:
            definition = message_definition(type_name).encode()
            self._schemas[type_name] = self._writer.register_schema(type_name, SCHEMA_ENCODING, definition)
        profiles = [Qos()] if qos is None else [qos] if isinstance(qos, Qos) else list(qos)
        digest = type_hash(type_name)
        metadata = {"offered_qos_profiles": offered_qos_yaml(profiles), "topic_type_hash": digest}
        channel_id = self._writer.register_channel(topic, MESSAGE_ENCODING, self._schemas[type_name], metadata)
        self._topics[topic] = _Topic(channel_id, type_name, profiles, digest)
        return channel_id

    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        """Write one raw CDR message; times in [ns], publish time defaults to the log time."""
        entry = self._entry(topic)
        publish = log_time_ns if publish_time_ns is None else publish_time_ns
        for t in (log_time_ns, publish):
            if not isinstance(t, int) or not 0 <= t < 2**64:
                raise BagError(f"{self.path}: time {t!r} on {topic} is not an integer ns >= 0")
        try:
            self._writer.add_message(entry.channel_id, log_time_ns, bytes(data), publish)
        except OSError as exc:  # e.g. a full disk: the file keeps every chunk completed before
            self.abandon()
            raise BagError(f"{self.path}: cannot write ({exc.strerror}); the bag is readable up to its last "
                           "complete chunk") from None
        entry.count += 1
        t0, t1 = self._times or (log_time_ns, log_time_ns)
        self._times = [min(t0, log_time_ns), max(t1, log_time_ns)]

    def write_message(self, topic: str, message: Any, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        """Encode `message` (rclpy message, namespace or dict; missing fields = defaults) to CDR
        with zero padding bytes, so equal messages give equal bytes, and write it; times in [ns]."""
        entry = self._entry(topic)
        cls = type(message)
        if hasattr(cls, "get_fields_and_field_types"):  # an rclpy message class
            actual = f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}"
            if actual != entry.type_name:
                raise BagError(f"{self.path}: {actual} written to {topic} ({entry.type_name})")
        encoder = self._encoders.get(entry.type_name)
        if encoder is None:
            definition = message_definition(entry.type_name)
            encoder = serialize_dynamic(entry.type_name, definition)[entry.type_name]
            self._encoders[entry.type_name] = encoder
        try:
            data = encoder(_Fields(message))
        except (ValueError, TypeError, struct.error, NotImplementedError) as exc:
            raise BagError(f"{self.path}: cannot encode {entry.type_name} on {topic}: {exc}") from None
        self.write(topic, data, log_time_ns, publish_time_ns)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """Add an MCAP metadata record `name` with string key/values (e.g. run facts)."""
        self._check_open()
        try:
            self._writer.add_metadata(name, {str(k): str(v) for k, v in data.items()})
        except OSError as exc:
            self.abandon()
            raise BagError(f"{self.path}: cannot write ({exc.strerror}); the bag is readable up to its last "
                           "complete chunk") from None

    def close(self) -> None:
        """Write the rosbag2 metadata record and the MCAP summary, then close the file."""
        if self._closed:
            return
        self._closed = True
        try:
            text = yaml.safe_dump(self._bag_metadata(), sort_keys=False, default_flow_style=False)
            self._writer.add_metadata("rosbag2", {"serialized_metadata": text})
            self._writer.finish()
        except OSError as exc:
            raise BagError(f"{self.path}: cannot finish the file ({exc.strerror}); it is readable up to its last "
                           "complete chunk") from None
        finally:
            try:
                self._file.close()
            except OSError:
                pass

    def abandon(self) -> None:
        """Close the file as it is, without the summary and footer (after a write error): a reader sees
        it truncated, readable up to its last complete chunk. Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            self._file.close()
        except OSError:
            pass

    def _check_open(self) -> None:
        if self._closed:
            raise BagError(f"{self.path}: bag writer is closed")

    def _entry(self, topic: str) -> _Topic:
        self._check_open()
        if topic not in self._topics:
            raise BagError(f"{self.path}: topic {topic} not added (call add_topic first)")
        return self._topics[topic]

    def _bag_metadata(self) -> dict[str, Any]:
        """rosbag2 BagMetadata (version 9) as rosbag2_storage/yaml.hpp encodes it."""
        start, end = self._times or (0, 0)
        count = sum(t.count for t in self._topics.values())

        def span() -> dict[str, Any]:  # fresh dicts: no YAML anchors
            return {
                "starting_time": {"nanoseconds_since_epoch": start},
                "duration": {"nanoseconds": end - start},
            }

        topics = [
            {
                "topic_metadata": {
                    "name": name,
                    "type": t.type_name,
                    "serialization_format": MESSAGE_ENCODING,
                    "offered_qos_profiles": [q.as_dict() for q in t.qos],
                    "type_description_hash": t.hash,
                },
                "message_count": t.count,
            }
            for name, t in self._topics.items()
        ]
        return {
            "version": METADATA_VERSION,
            "storage_identifier": "mcap",
            "duration": span()["duration"],
            "starting_time": span()["starting_time"],
            "message_count": count,
            "topics_with_message_count": topics,
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [self.path.name],
            "files": [{"path": self.path.name, **span(), "message_count": count}],
            "custom_data": None,
            "ros_distro": self._ros_distro,
        }


# ----------------------------------------------------------------------------- reading


@dataclass(frozen=True)
class BagMessage:
    """One message: topic, type `pkg/msg/Type`, times [ns], raw CDR and the decoded message."""

    topic: str
    type_name: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes
    message: Any  # mcap_ros2 decoded object (msg.header.stamp.sec), None if not decoded


@dataclass
class BagContents:
    """What `read_bag` found; `truncated` = no footer (writer killed), complete chunks were read."""

    path: Path
    messages: list[BagMessage] = field(default_factory=list)
    topics: dict[str, str] = field(default_factory=dict)  # topic -> type name
    counts: dict[str, int] = field(default_factory=dict)  # topic -> messages read
    truncated: bool = False
    last_time_ns: int | None = None  # latest log time read [ns]
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)  # MCAP metadata records


class _Limited:
    """Read-only view of the first `end` bytes of a binary file."""

    def __init__(self, file: IO[bytes], end: int) -> None:
        self._file, self._end = file, end

    def read(self, size: int = -1) -> bytes:
        left = self._end - self._file.tell()
        return self._file.read(left if size < 0 else min(size, left))


def _check(path: Path) -> tuple[int, bool]:
    """(bytes of complete records, file has its footer) or a BagError for unusable files."""
    if not path.exists():
        raise BagError(f"{path}: no such file")
    if path.is_dir():
        raise BagError(f"{path}: is a directory, not an MCAP file")
    size = path.stat().st_size
    if size == 0:
        raise BagError(f"{path}: empty file (0 bytes)")
    with path.open("rb") as f:
        if f.read(8) != MAGIC:
            raise BagError(f"{path}: not an MCAP file (bad magic bytes)")
        if size >= 8 + 37:  # footer record (9 + 20 bytes) and closing magic (8 bytes)
            f.seek(size - 37)
            tail = f.read(37)
            if tail[:9] == b"\x02" + struct.pack("<Q", 20) and tail[-8:] == MAGIC:
                return size, True
        pos = 8
        while pos + 9 <= size:  # walk record headers: opcode (1 B) + length (8 B)
            f.seek(pos + 1)
            end = pos + 9 + struct.unpack("<Q", f.read(8))[0]
            if end > size:
                break
            pos = end
        return pos, False


_READ_ERRORS: tuple[type[BaseException], ...] = (McapError, ValueError, struct.error, RuntimeError)
try:
    from zstandard import ZstdError

    _READ_ERRORS += (ZstdError,)
except ImportError:  # pragma: no cover
    pass


def _read(path: Path, only: Iterable[str] | None, decode: bool, keep: bool) -> BagContents:
    """Stream the complete records of `path` (optionally only some topics) into BagContents."""
    end, complete = _check(path)
    wanted = None if only is None else set(only)
    out = BagContents(path=path, truncated=not complete)
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    decoders: dict[int, Callable[[bytes], Any]] = {}
    factory = DecoderFactory()

    def decoded(channel: Channel, data: bytes) -> Any:
        if channel.id not in decoders:
            schema = schemas.get(channel.schema_id)
            try:
                found = factory.decoder_for(channel.message_encoding, schema)
            except (McapError, ValueError) as exc:
                raise BagError(f"{path}: bad schema for {channel.topic}: {exc}") from None
            if found is None:
                kind = f"{channel.message_encoding}/{schema.encoding if schema else 'no schema'}"
                raise BagError(f"{path}: cannot decode {channel.topic} ({kind}, need cdr/ros2msg)")
            decoders[channel.id] = found
        try:
            return decoders[channel.id](data)
        except (ValueError, IndexError, struct.error, UnicodeDecodeError) as exc:
            raise BagError(f"{path}: cannot decode a message on {channel.topic}: {exc}") from None

    with path.open("rb") as f:
        source: Any = _Limited(f, end)
        records = StreamReader(source).records
        while True:
            try:
                record = next(records)
            except StopIteration:
                break
            except EndOfFile:  # the normal end of a truncated file
                if complete:
                    raise BagError(f"{path}: corrupt MCAP data (records end early)") from None
                break
            except _READ_ERRORS as exc:
                raise BagError(f"{path}: corrupt MCAP data ({exc})") from None
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
                schema = schemas.get(record.schema_id)
                out.topics[record.topic] = schema.name if schema else ""
                out.counts.setdefault(record.topic, 0)
            elif isinstance(record, Metadata):
                out.metadata[record.name] = dict(record.metadata)
            elif isinstance(record, Message):
                channel = channels.get(record.channel_id)
                if channel is None:
                    raise BagError(f"{path}: message on unknown channel {record.channel_id}")
                if wanted is not None and channel.topic not in wanted:
                    continue
                out.counts[channel.topic] += 1
                last = out.last_time_ns
                out.last_time_ns = record.log_time if last is None else max(last, record.log_time)
                if keep:
                    value = decoded(channel, record.data) if decode else None
                    type_name = out.topics[channel.topic]
                    times = (record.log_time, record.publish_time)
                    out.messages.append(BagMessage(channel.topic, type_name, *times, record.data, value))
    if wanted is not None:
        out.topics = {k: v for k, v in out.topics.items() if k in wanted}
        out.counts = {k: v for k, v in out.counts.items() if k in wanted}
    return out


def read_bag(path: str | os.PathLike[str], topics: Iterable[str] | None = None, decode: bool = True) -> BagContents:
    """Read every message (of `topics`, default all) in file order, decoded unless `decode=False`.

    A file without footer (writer killed) gives the messages of all complete chunks and
    `truncated=True`; a missing, empty, non-MCAP or corrupt file raises BagError.
    """
    return _read(Path(path), topics, decode, keep=True)


def _topics_and_counts(path: Path) -> tuple[dict[str, str], dict[str, int]]:
    """(topic -> type, topic -> messages) from the summary if there is one, else by scanning."""
    _, complete = _check(path)
    summary = None
    if complete:
        with path.open("rb") as f:
            try:
                summary = make_reader(f).get_summary()
            except _READ_ERRORS:
                summary = None
    if summary is None or summary.statistics is None:
        scan = _read(path, None, decode=False, keep=False)
        return scan.topics, scan.counts
    names: dict[str, str] = {}
    counts: dict[str, int] = {}
    stats = summary.statistics.channel_message_counts
    for cid, channel in summary.channels.items():
        schema = summary.schemas.get(channel.schema_id)
        names[channel.topic] = schema.name if schema else ""
        counts[channel.topic] = counts.get(channel.topic, 0) + stats.get(cid, 0)
    return names, counts


def topics(path: str | os.PathLike[str]) -> dict[str, str]:
    """Topic -> type name `pkg/msg/Type`, from the summary when present, else by scanning."""
    return _topics_and_counts(Path(path))[0]


def message_counts(path: str | os.PathLike[str]) -> dict[str, int]:
    """Topic -> number of messages, from the summary statistics when present, else by scanning."""
    return _topics_and_counts(Path(path))[1]


def write_metadata_yaml(path: str | os.PathLike[str]) -> Path:
    """Write `metadata.yaml` next to the bag from its `rosbag2` record (a rosbag2 bag directory)."""
    p = Path(path)
    _, complete = _check(p)
    with p.open("rb") as f:
        records = list(make_reader(f).iter_metadata()) if complete else []
    texts = [r.metadata.get("serialized_metadata", "") for r in records if r.name == "rosbag2"]
    if not texts or not texts[-1]:
        raise BagError(f"{p}: no rosbag2 metadata record (file truncated or not from BagWriter)")
    info = yaml.safe_load(texts[-1])
    target = p.parent / "metadata.yaml"
    text = yaml.safe_dump({"rosbag2_bagfile_information": info}, sort_keys=False)
    target.write_text(text, encoding="utf-8")
    return target


__all__ = [
    "DURATION_INFINITE",
    "default_bag_name",
    "BagContents",
    "BagMessage",
    "BagWriter",
    "Qos",
    "message_counts",
    "message_definition",
    "offered_qos_yaml",
    "read_bag",
    "topics",
    "type_hash",
    "write_metadata_yaml",
]
