"""Read rosbag2 MCAP bags (ours and ``ros2 bag record``'s), salvaging truncated files.

:class:`BagReader` accepts a bag directory (``metadata.yaml`` + ``*.mcap``, or only the
``*.mcap`` files when the recorder died before writing ``metadata.yaml``) or a single
``.mcap`` file. It walks each file record by record — its own framing loop with bounds
checks around the ``mcap`` package's record parsers — so that:

* a complete file reads in full (chunked or not, compressed or not);
* a file cut short (recorder killed, disk full) yields every record that is complete
  before the cut, and the reader says so (``salvaged``, ``problems``: file, offset, what);
  a record cut in the middle is dropped, never returned with short data;
* anything malformed or not a ROS 2 bag (bad magic, unknown channel, non-CDR encoding, a
  topic with two types, unreadable QoS) raises :class:`~pearl_pomdp.errors.PearlError`
  naming the file, the offset or topic, and what is wrong.

Messages come in file order (rosbag2 writes them in receive order). The whole bag is read
into memory at open: bags here are scenario recordings, not hours of sensor data.
"""
from __future__ import annotations

import io
import os
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, Iterator, List, Optional, Sequence, Union

from pearl_pomdp.bags import metadata as md
from pearl_pomdp.bags import well_known as wk
from pearl_pomdp.bags.metadata import QosProfile
from pearl_pomdp.errors import PearlError

PathLike = Union[str, os.PathLike]
_MAGIC = b"\x89MCAP0\r\n"
_MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time


class BagError(PearlError):
    """A bag is unreadable, malformed or not a ROS 2 (rosbag2 'ros2' profile) bag."""


@dataclass(frozen=True)
class BagMessage:
    """One recorded message: ``data`` is the CDR bytes as on the wire; times in ns."""

    topic: str
    type: str
    log_time: int
    publish_time: int
    sequence: int
    data: bytes


@dataclass
class TopicInfo:
    """A topic of a bag: type, serialization, QoS offered by its publishers, type hash, count."""

    name: str
    type: str
    serialization_format: str
    offered_qos_profiles: List[QosProfile]
    type_description_hash: str
    message_count: int = 0
    schema_encoding: str = wk.SCHEMA_ENCODING
    definition: str = ""


@dataclass
class _FileScan:
    path: Path
    profile: Optional[str] = None
    library: Optional[str] = None
    complete: bool = False
    problem: Optional[str] = None
    rosbag2_metadata: Optional[Dict[str, Any]] = None
    statistics_count: Optional[int] = None
    messages: List[BagMessage] = field(default_factory=list)


class BagReader:
    """All messages and topics of a bag, read at construction.

    Args:
        path: a bag directory or an ``.mcap`` file.
        salvage: when ``True`` (default) a truncated file gives the messages before the cut
            (``salvaged`` becomes ``True``, ``problems`` says where); when ``False`` it raises.

    Attributes:
        topics: ``{name: TopicInfo}`` in order of first appearance.
        messages: every message, in file order.
        files: the MCAP files read.
        metadata: the ``rosbag2_bagfile_information`` mapping from ``metadata.yaml`` (or from
            the MCAP ``rosbag2`` record when there is no ``metadata.yaml``), else ``None``.
        salvaged: whether any file was cut short and read up to the cut.
        problems: one line per salvaged file (file, offset, what was incomplete).
        library: the MCAP header's library string of the first file.
    """

    def __init__(self, path: PathLike, *, salvage: bool = True):
        self.path = Path(path)
        self.salvage = salvage
        self.topics: Dict[str, TopicInfo] = {}
        self.messages: List[BagMessage] = []
        self.problems: List[str] = []
        self.metadata: Optional[Dict[str, Any]] = None
        self.metadata_file: Optional[Path] = None
        self.library: Optional[str] = None
        self.files = self._resolve()
        for f in self.files:
            scan = self._scan(f)
            if scan.problem:
                self.problems.append(scan.problem)
            if self.library is None:
                self.library = scan.library
            if self.metadata is None and scan.rosbag2_metadata is not None:
                self.metadata = scan.rosbag2_metadata
            self.messages.extend(scan.messages)
        for m in self.messages:
            self.topics[m.topic].message_count += 1

    # -- summary ----------------------------------------------------------------------------
    @property
    def salvaged(self) -> bool:
        return bool(self.problems)

    @property
    def message_count(self) -> int:
        return len(self.messages)

    @property
    def start_time(self) -> Optional[int]:
        """Earliest log time (ns), ``None`` for an empty bag."""
        return min((m.log_time for m in self.messages), default=None)

    @property
    def end_time(self) -> Optional[int]:
        """Latest log time (ns), ``None`` for an empty bag."""
        return max((m.log_time for m in self.messages), default=None)

    @property
    def duration(self) -> int:
        """``end_time - start_time`` in ns (0 for an empty bag)."""
        start, end = self.start_time, self.end_time
        return end - start if (start is not None and end is not None) else 0

    def read_messages(self, topics: Optional[Iterable[str]] = None) -> Iterator[BagMessage]:
        """Messages in file order, optionally only those of ``topics``."""
        wanted = None if topics is None else set(topics)
        for m in self.messages:
            if wanted is None or m.topic in wanted:
                yield m

    def decoder(self, topic: str) -> Callable[[bytes], Any]:
        """``bytes -> message`` for ``topic``: an object with the message's fields, decoded from the
        definition the bag itself holds (``mcap-ros2-support``; no ROS import, and the type need not
        be installed).

        Raises:
            BagError: ``topic`` is not in the bag or its schema holds no definition (names bag and topic).
        """
        from mcap.records import Schema
        from mcap_ros2.decoder import DecoderFactory

        info = self.topics.get(topic)
        if info is None:
            raise BagError(f"{self.path}: no topic {topic} (topics: {', '.join(self.topics) or 'none'})")
        if not info.definition.strip():
            raise BagError(f"{self.path}: topic {topic}: its schema {info.type} holds no message definition")
        schema = Schema(id=1, name=info.type, encoding=info.schema_encoding, data=info.definition.encode("utf-8"))
        decode = DecoderFactory().decoder_for(wk.MESSAGE_ENCODING, schema)
        assert decode is not None   # (the factory decodes every cdr + ros2msg channel)
        return decode

    # -- locating files ---------------------------------------------------------------------
    def _resolve(self) -> List[Path]:
        p = self.path
        if not p.exists():
            raise BagError(f"{p}: no such bag (directory or .mcap file)")
        if p.is_file():
            return [p]
        meta_path = p / wk.METADATA_FILENAME
        if meta_path.is_file():
            self.metadata_file = meta_path
            self.metadata = self._read_metadata_yaml(meta_path)
            storage = self.metadata.get("storage_identifier")
            if storage != wk.STORAGE_IDENTIFIER:
                raise BagError(f"{meta_path}: storage_identifier: {storage!r} is not supported "
                               f"(only 'mcap'; convert sqlite3 bags with `ros2 bag convert`)")
            if str(self.metadata.get("compression_mode") or "").lower() in ("file", "message"):
                raise BagError(f"{meta_path}: compression_mode: {self.metadata['compression_mode']!r} "
                               f"compression is not supported (only MCAP chunk compression)")
            rel = self.metadata.get("relative_file_paths") or []
            if not isinstance(rel, list) or not rel:
                raise BagError(f"{meta_path}: relative_file_paths: expected a non-empty list")
            files = []
            for r in rel:
                candidate = p / str(r)
                if not candidate.is_file():
                    candidate2 = p / Path(str(r)).name
                    if not candidate2.is_file():
                        raise BagError(f"{meta_path}: relative_file_paths: {r} does not exist in {p}")
                    candidate = candidate2
                files.append(candidate)
            return files
        files = sorted(p.glob(f"*{wk.MCAP_SUFFIX}"), key=_file_order)
        if not files:
            raise BagError(f"{p}: not a bag: no {wk.METADATA_FILENAME} and no *.mcap file")
        return files

    @staticmethod
    def _read_metadata_yaml(path: Path) -> Dict[str, Any]:
        import yaml

        try:
            doc = md.load_yaml(path.read_text(encoding="utf-8"))
        except (yaml.YAMLError, UnicodeDecodeError) as err:
            line = getattr(getattr(err, "problem_mark", None), "line", None)
            where = f"{path}:{line + 1}" if line is not None else str(path)
            raise BagError(f"{where}: metadata.yaml is not valid YAML ({getattr(err, 'problem', err)})") from None
        if not isinstance(doc, dict) or not isinstance(doc.get(wk.METADATA_TOP_KEY), dict):
            raise BagError(f"{path}: {wk.METADATA_TOP_KEY}: missing (not a rosbag2 metadata.yaml)")
        info = doc[wk.METADATA_TOP_KEY]
        version = info.get("version")
        if not isinstance(version, int) or version < 1:
            raise BagError(f"{path}: {wk.METADATA_TOP_KEY}.version: expected an integer, got {version!r}")
        return info

    # -- scanning one MCAP file -------------------------------------------------------------
    def _fail(self, path: Path, offset: int, what: str) -> BagError:
        return BagError(f"{path}: offset {offset}: {what}")

    def _scan(self, path: Path) -> _FileScan:
        from mcap import records as rec
        from mcap.opcode import Opcode

        scan = _FileScan(path=path)
        try:
            buf = path.read_bytes()
        except OSError as err:
            raise BagError(f"{path}: cannot read ({err.strerror})") from None
        size = len(buf)
        if size < len(_MAGIC) or buf[:8] != _MAGIC:
            if size < len(_MAGIC) and _MAGIC.startswith(buf):
                raise BagError(f"{path}: offset 0: file is empty or cut inside the MCAP magic "
                               f"({size} bytes); nothing to salvage")
            raise BagError(f"{path}: offset 0: not an MCAP file (bad magic)")
        schemas: Dict[int, Any] = {}
        channels: Dict[int, TopicInfo] = {}
        pos = 8
        in_summary = False

        def cut(offset: int, what: str) -> None:
            msg = f"{path}: truncated at offset {offset} of {size}: {what}"
            if not self.salvage:
                raise BagError(msg + " (the recorder did not close it; `pearl bag-info` salvages)")
            scan.problem = msg

        while True:
            if pos == size:
                cut(pos, "no footer (file ends after a complete record)")
                break
            if pos + 9 > size:
                cut(pos, f"incomplete record header ({size - pos} of 9 bytes)")
                break
            opcode = buf[pos]
            (length,) = struct.unpack_from("<Q", buf, pos + 1)
            body_start, end = pos + 9, pos + 9 + length
            if end > size:
                try:
                    name = Opcode(opcode).name
                except ValueError:
                    name = f"opcode 0x{opcode:02x}"
                cut(pos, f"incomplete {name} record ({size - body_start} of {length} bytes)")
                break
            body = buf[body_start:end]
            try:
                if opcode == Opcode.MESSAGE:
                    if not in_summary:
                        scan.messages.append(self._message(path, pos, body, channels))
                elif opcode == Opcode.CHUNK:
                    chunk = rec.Chunk.read(_strict(body))
                    for r in _chunk_records(chunk):
                        self._record(path, pos, r, schemas, channels, scan)
                elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.HEADER, Opcode.METADATA,
                                Opcode.STATISTICS):
                    parser: Any = {Opcode.SCHEMA: rec.Schema, Opcode.CHANNEL: rec.Channel, Opcode.HEADER: rec.Header,
                                   Opcode.METADATA: rec.Metadata, Opcode.STATISTICS: rec.Statistics}[Opcode(opcode)]
                    r = parser.read(_strict(body))
                    # The summary repeats schemas and channels; only ones not seen are new
                    # (a writer may put a channel without messages only there).
                    repeated = in_summary and ((opcode == Opcode.SCHEMA and r.id in schemas)
                                               or (opcode == Opcode.CHANNEL and r.id in channels))
                    if not repeated:
                        self._record(path, pos, r, schemas, channels, scan)
                elif opcode == Opcode.DATA_END:
                    in_summary = True
                elif opcode == Opcode.FOOTER:
                    if buf[end:end + 8] != _MAGIC:
                        cut(end, "footer not followed by the closing MCAP magic")
                    else:
                        scan.complete = True
                    break
                # other records (indexes, attachments, summary offsets) carry nothing we need
            except BagError:
                raise
            except (struct.error, ValueError, UnicodeDecodeError, EOFError, KeyError) as err:
                raise self._fail(path, pos, f"malformed record (opcode 0x{opcode:02x}): {err or type(err).__name__}")
            except Exception as err:  # mcap's EndOfFile / CRC / decompression errors
                if type(err).__module__.startswith(("mcap", "zstandard", "lz4")):
                    raise self._fail(path, pos, f"malformed record (opcode 0x{opcode:02x}): "
                                                f"{type(err).__name__} {err}".rstrip())
                raise
            pos = end
        if scan.profile is None and scan.messages:
            raise BagError(f"{path}: offset 8: no MCAP header record")
        return scan

    def _message(self, path: Path, offset: int, body: bytes, channels: Dict[int, TopicInfo]) -> BagMessage:
        if len(body) < _MESSAGE_HEAD.size:
            raise self._fail(path, offset, f"Message record of {len(body)} bytes is shorter than its header")
        channel_id, seq, log_time, publish_time = _MESSAGE_HEAD.unpack_from(body)
        topic = channels.get(channel_id)
        if topic is None:
            raise self._fail(path, offset, f"message on channel {channel_id}, which no Channel record defines")
        return BagMessage(topic.name, topic.type, log_time, publish_time, seq, bytes(body[_MESSAGE_HEAD.size:]))

    def _record(self, path: Path, offset: int, r: Any, schemas: Dict[int, Any],
                channels: Dict[int, TopicInfo], scan: _FileScan) -> None:
        from mcap import records as rec

        if isinstance(r, rec.Message):
            topic = channels.get(r.channel_id)
            if topic is None:
                raise self._fail(path, offset, f"message on channel {r.channel_id}, which no Channel record defines")
            scan.messages.append(BagMessage(topic.name, topic.type, r.log_time, r.publish_time, r.sequence, bytes(r.data)))
        elif isinstance(r, rec.Header):
            scan.profile, scan.library = r.profile, r.library
            if r.profile != wk.PROFILE:
                raise self._fail(path, offset, f"MCAP profile {r.profile!r}, expected {wk.PROFILE!r} (not a ROS 2 bag)")
        elif isinstance(r, rec.Schema):
            schemas[r.id] = r
        elif isinstance(r, rec.Channel):
            self._channel(path, offset, r, schemas, channels)
        elif isinstance(r, rec.Metadata) and r.name == wk.METADATA_RECORD_NAME:
            text = r.metadata.get(wk.METADATA_RECORD_KEY)
            if text:
                import yaml

                try:
                    doc = md.load_yaml(text)
                except yaml.YAMLError as err:
                    raise self._fail(path, offset, f"rosbag2 metadata record is not YAML ({err})") from None
                if isinstance(doc, dict):
                    scan.rosbag2_metadata = doc
        elif isinstance(r, rec.Statistics):
            scan.statistics_count = r.message_count

    def _channel(self, path: Path, offset: int, r: Any, schemas: Dict[int, Any],
                 channels: Dict[int, TopicInfo]) -> None:
        where = f"{path}: offset {offset}: topic {r.topic}"
        if r.message_encoding != wk.MESSAGE_ENCODING:
            raise BagError(f"{where}: message encoding {r.message_encoding!r}, expected {wk.MESSAGE_ENCODING!r}")
        schema = schemas.get(r.schema_id)
        if schema is None:
            raise BagError(f"{where}: channel names schema {r.schema_id}, which no Schema record defines")
        if schema.encoding not in (wk.SCHEMA_ENCODING, wk.SCHEMA_ENCODING_IDL):
            raise BagError(f"{where}: schema encoding {schema.encoding!r}, expected {wk.SCHEMA_ENCODING!r}")
        qos = md.parse_qos_list(r.metadata.get(wk.CHANNEL_QOS_KEY, ""), where)
        type_hash = r.metadata.get(wk.CHANNEL_TYPE_HASH_KEY, "")
        existing = self.topics.get(r.topic)
        if existing is not None:
            if existing.type != schema.name:
                raise BagError(f"{where}: recorded as {schema.name} here but as {existing.type} before")
            channels[r.id] = existing
            return
        try:
            definition = schema.data.decode("utf-8")
        except UnicodeDecodeError:
            raise BagError(f"{where}: schema {schema.name} definition is not UTF-8") from None
        info = TopicInfo(name=r.topic, type=schema.name, serialization_format=r.message_encoding,
                         offered_qos_profiles=qos, type_description_hash=type_hash,
                         schema_encoding=schema.encoding, definition=definition)
        self.topics[r.topic] = info
        channels[r.id] = info


_STRICT = None


def _strict(body: bytes):
    """A ReadDataStream over ``body`` that raises instead of returning short reads."""
    global _STRICT
    if _STRICT is None:
        from mcap.data_stream import ReadDataStream
        from mcap.exceptions import EndOfFile

        class _Strict(ReadDataStream):
            def read(self, length: int) -> bytes:
                data = super().read(length)
                if len(data) != length:
                    raise EndOfFile()
                return data

        _STRICT = _Strict
    return _STRICT(io.BytesIO(body))


def _chunk_records(chunk) -> Sequence[Any]:
    from mcap.stream_reader import breakup_chunk

    return breakup_chunk(chunk, validate_crc=True)


def _file_order(path: Path):
    """A split bag's files in the order written (``NAME_2.mcap`` before ``NAME_10.mcap``), then by name."""
    stem, _, index = path.stem.rpartition("_")
    return (stem, int(index), path.name) if index.isdigit() else (path.stem, -1, path.name)


def cdr_string(data: bytes, offset: int = 0) -> str:
    """The ``data`` field of a CDR-encoded std_msgs/String (no ROS import needed); ``offset``: bytes
    of the message before its string (8 for ``pearl_interfaces/Action``, whose stamp comes first).

    Raises:
        ValueError: the bytes are too short for the string they announce.
    """
    start = 4 + offset
    if len(data) < start + 4:
        raise ValueError("shorter than its CDR string")
    (n,) = struct.unpack_from("<I" if data[1] == 1 else ">I", data, start)
    if n == 0 or start + 4 + n > len(data):
        raise ValueError(f"string length {n} does not fit in {len(data)} bytes")
    return data[start + 4:start + 4 + n - 1].decode("utf-8")


def open_bag(path: PathLike, *, salvage: bool = True) -> BagReader:
    """Shorthand for :class:`BagReader`."""
    return BagReader(path, salvage=salvage)
