"""Write rosbag2 bags: MCAP with the 'ros2' profile, plus ``metadata.yaml`` (version 9).

A bag is a directory ``NAME/`` holding ``NAME_0.mcap`` and, once closed, ``metadata.yaml``
— the layout of ``ros2 bag record -s mcap``. With ``max_duration_ns`` (rosbag2's
``--max-bag-duration``) the bag is split: a message logged that long after its file's first one
starts ``NAME_1.mcap``, and so on; every file is a whole MCAP file with every schema and channel,
and ``metadata.yaml`` lists them in order. Inside the MCAP file, as rosbag2_storage_mcap
writes them: header profile ``ros2``; one ``ros2msg`` schema per type with rosbag2's full
definition text (:mod:`pearl_pomdp.bags.msgdefs`); one ``cdr`` channel per topic with
metadata ``offered_qos_profiles`` and ``topic_type_hash``; messages with log (receive) and
publish times in nanoseconds; at close, the ``rosbag2`` metadata record holding
``serialized_metadata``.

Crash safety: by default the file is *unchunked* (rosbag2's ``fastwrite`` preset) and every
record is flushed to the operating system as it is written, so a recorder killed with
SIGKILL leaves every message written before the kill in the file (no footer or summary;
:class:`~pearl_pomdp.bags.reader.BagReader` salvages it). ``chunk_size=`` writes chunked
files instead (smaller, indexed); then messages of the unfinished chunk are lost on a kill.
``metadata.yaml`` is written atomically (temporary file + rename): it is either absent or
complete.

Example::

    with BagWriter("out/run1") as bag:
        bag.add_topic("/pearl/speech", "std_msgs/msg/String", qos=[QosProfile()])
        bag.write("/pearl/speech", cdr_bytes, log_time_ns)
"""
from __future__ import annotations

import os
import threading
import time
from pathlib import Path
from typing import Dict, Mapping, Optional, Sequence, Union

from pearl_pomdp.atomic import atomic_write
from pearl_pomdp.bags import metadata as md
from pearl_pomdp.bags import msgdefs
from pearl_pomdp.bags import well_known as wk
from pearl_pomdp.bags.metadata import QosProfile, TopicMetadata
from pearl_pomdp.errors import PearlError

PathLike = Union[str, os.PathLike]


def _library() -> str:
    from pearl_pomdp import __version__

    try:
        from importlib.metadata import version

        mcap_version = version("mcap")
    except Exception:  # pragma: no cover - metadata missing in odd installs
        mcap_version = "?"
    return f"pearl_pomdp {__version__}; mcap-python {mcap_version}"


class _Topic:
    __slots__ = ("meta", "channel_id", "count", "sequence")

    def __init__(self, meta: TopicMetadata, channel_id: int):
        self.meta = meta
        self.channel_id = channel_id
        self.count = 0
        self.sequence = 0


class BagWriter:
    """Writer of one rosbag2 'ros2'-profile MCAP bag (a context manager; thread-safe).

    Args:
        path: the bag directory to create (must not exist, or be empty).
        chunk_size: ``None`` (default) writes unchunked, crash-safe records; an int writes
            chunks of about that many bytes (lost up to one chunk on a kill).
        compression: ``"none"`` or ``"zstd"``/``"lz4"`` (chunked files only).
        flush_each: flush each record to the OS at once (default ``True``).
        custom_data: ``custom_data`` of ``metadata.yaml`` (string → string).
        ros_distro: written to ``metadata.yaml`` (``jazzy``).
        max_duration_ns: split the bag into files of at most this much log time each (``None``: one file).
    """

    def __init__(self, path: PathLike, *, chunk_size: Optional[int] = None, compression: str = "none",
                 flush_each: bool = True, custom_data: Optional[Mapping[str, str]] = None,
                 ros_distro: str = wk.ROS_DISTRO, max_duration_ns: Optional[int] = None):
        from mcap.writer import CompressionType

        if max_duration_ns is not None and int(max_duration_ns) <= 0:
            raise PearlError(f"max_duration_ns {max_duration_ns}: a bag file's duration must be positive")
        self.path = Path(path)
        if self.path.suffix == wk.MCAP_SUFFIX:
            raise PearlError(f"{self.path}: a bag is a directory (rosbag2 layout); give a name without .mcap")
        if self.path.exists() and (not self.path.is_dir() or any(self.path.iterdir())):
            raise PearlError(f"{self.path}: already exists; choose a new bag name")
        compressions = {"none": CompressionType.NONE, "zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}
        if compression not in compressions:
            raise PearlError(f"compression {compression!r}: expected one of {sorted(compressions)}")
        if compression != "none" and chunk_size is None:
            raise PearlError("compression needs chunk_size (MCAP compresses chunks)")
        self.path.mkdir(parents=True, exist_ok=True)
        self._chunk_size = chunk_size
        self._compression = compressions[compression]
        self._max_duration = None if max_duration_ns is None else int(max_duration_ns)
        #: Closed files: (name, first log time, duration, messages), in order.
        self._done_files: list = []
        self._file_start: Optional[int] = None
        self._file_end: Optional[int] = None
        self._file_count = 0
        self._definitions: Dict[str, str] = {}
        self._open_file(0)
        self._flush_each = flush_each
        self._custom_data = dict(custom_data or {})
        self._ros_distro = ros_distro
        self._schemas: Dict[str, int] = {}
        self._topics: Dict[str, _Topic] = {}
        self._lock = threading.Lock()
        self._start: Optional[int] = None
        self._end: Optional[int] = None
        self.message_count = 0
        self.closed = False
        # An early ``rosbag2`` metadata record: a bag whose recorder is killed keeps its
        # custom_data and distro (rosbag2 readers take the last such record, i.e. the one
        # written at close when there is one).
        self._writer.add_metadata(wk.METADATA_RECORD_NAME, {wk.METADATA_RECORD_KEY: md.dump_yaml(self.metadata())})
        self._flush()

    def _open_file(self, index: int) -> None:
        from mcap.writer import Writer

        self.mcap_path = self.path / f"{self.path.name}_{index}{wk.MCAP_SUFFIX}"
        self._file = open(self.mcap_path, "wb")
        self._writer = Writer(self._file, chunk_size=self._chunk_size or 1024 * 1024, compression=self._compression,
                              use_chunking=self._chunk_size is not None, enable_crcs=True)
        self._writer.start(profile=wk.PROFILE, library=_library())

    def _finish_file(self) -> None:
        """The current file's metadata record, summary and footer; synced and closed."""
        self._writer.add_metadata(wk.METADATA_RECORD_NAME, {wk.METADATA_RECORD_KEY: md.dump_yaml(self.metadata())})
        self._writer.finish()
        self._file.flush()
        os.fsync(self._file.fileno())
        self._file.close()

    def _roll(self) -> None:
        """Close the current file and open the next, every schema and channel registered again."""
        start = self._file_start or 0
        self._done_files.append((self.mcap_path.name, start, (self._file_end or start) - start, self._file_count))
        self._finish_file()
        self._open_file(len(self._done_files))
        self._file_start = self._file_end = None
        self._file_count = 0
        schemas: Dict[str, int] = {}
        for type_name, definition in self._definitions.items():
            schemas[type_name] = self._writer.register_schema(name=type_name, encoding=wk.SCHEMA_ENCODING,
                                                              data=definition.encode("utf-8"))
        self._schemas = schemas
        for t in self._topics.values():
            t.channel_id = self._writer.register_channel(
                topic=t.meta.name, message_encoding=t.meta.serialization_format, schema_id=schemas[t.meta.type],
                metadata={wk.CHANNEL_QOS_KEY: md.qos_list_yaml(t.meta.offered_qos_profiles),
                          wk.CHANNEL_TYPE_HASH_KEY: t.meta.type_description_hash})
        # As at the start: a file whose recorder is killed still carries the bag's metadata.
        self._writer.add_metadata(wk.METADATA_RECORD_NAME, {wk.METADATA_RECORD_KEY: md.dump_yaml(self.metadata())})
        self._flush()

    # -- topics -----------------------------------------------------------------------------
    def add_topic(self, name: str, type_name: str, *, qos: Sequence[QosProfile] = (),
                  type_hash: Optional[str] = None, definition: Optional[str] = None,
                  serialization_format: str = wk.SERIALIZATION_FORMAT) -> int:
        """Register a topic (schema + channel); returns its MCAP channel id.

        ``definition`` and ``type_hash`` default to rosbag2's text and the RIHS01 hash from
        the installed interface files; a type whose files are missing gets an empty
        definition (encoding ``ros2msg``) and hash, as rosbag2 does when it cannot find one.
        """
        with self._lock:
            self._check_open()
            if name in self._topics:
                existing = self._topics[name].meta
                if existing.type != type_name:
                    raise PearlError(f"{self.path}: topic {name} already registered as {existing.type}, not {type_name}")
                return self._topics[name].channel_id
            if definition is None:
                try:
                    definition = msgdefs.message_definition(type_name)
                except PearlError:
                    definition = ""
            if type_hash is None:
                type_hash = msgdefs.try_type_hash(type_name) or ""
            schema_id = self._schemas.get(type_name)
            if schema_id is None:
                schema_id = self._writer.register_schema(
                    name=type_name, encoding=wk.SCHEMA_ENCODING, data=definition.encode("utf-8"))
                self._schemas[type_name] = schema_id
                self._definitions[type_name] = definition
            meta = TopicMetadata(name=name, type=type_name, serialization_format=serialization_format,
                                 offered_qos_profiles=list(qos), type_description_hash=type_hash)
            channel_id = self._writer.register_channel(
                topic=name, message_encoding=serialization_format, schema_id=schema_id,
                metadata={wk.CHANNEL_QOS_KEY: md.qos_list_yaml(meta.offered_qos_profiles),
                          wk.CHANNEL_TYPE_HASH_KEY: type_hash})
            self._topics[name] = _Topic(meta, channel_id)
            self._flush()
            return channel_id

    @property
    def topics(self) -> Dict[str, TopicMetadata]:
        """Registered topics by name."""
        return {n: t.meta for n, t in self._topics.items()}

    # -- messages ---------------------------------------------------------------------------
    def write(self, topic: str, data: bytes, log_time: int, publish_time: Optional[int] = None,
              sequence: Optional[int] = None) -> None:
        """Append one serialized (CDR) message.

        Args:
            topic: a topic registered with :meth:`add_topic`.
            data: the message bytes exactly as on the wire.
            log_time: receive time, ns since the epoch (or sim-time origin).
            publish_time: source (publish) time in ns; defaults to ``log_time``.
            sequence: publisher sequence number; defaults to a per-topic counter from 1.
        """
        if not isinstance(data, (bytes, bytearray, memoryview)):
            raise TypeError(f"message data must be bytes, got {type(data).__name__}")
        log_time = int(log_time)
        publish_time = log_time if publish_time is None else int(publish_time)
        if log_time < 0 or publish_time < 0:
            raise PearlError(f"{self.path}: {topic}: negative timestamp {min(log_time, publish_time)} ns")
        with self._lock:
            self._check_open()
            t = self._topics.get(topic)
            if t is None:
                raise PearlError(f"{self.path}: topic {topic} was not added (add_topic first)")
            if (self._max_duration is not None and self._file_start is not None
                    and log_time - self._file_start >= self._max_duration):
                self._roll()
            t.sequence += 1
            seq = t.sequence if sequence is None else int(sequence)
            self._writer.add_message(channel_id=t.channel_id, log_time=log_time, data=bytes(data),
                                     publish_time=publish_time, sequence=seq & 0xFFFFFFFF)
            t.count += 1
            self.message_count += 1
            self._file_count += 1
            self._file_start = log_time if self._file_start is None else min(self._file_start, log_time)
            self._file_end = log_time if self._file_end is None else max(self._file_end, log_time)
            self._start = log_time if self._start is None else min(self._start, log_time)
            self._end = log_time if self._end is None else max(self._end, log_time)
            self._flush()

    def flush(self) -> None:
        """Push written records to the operating system (what survives a SIGKILL)."""
        with self._lock:
            if not self.closed:
                self._file.flush()

    def _flush(self) -> None:
        if self._flush_each:
            self._file.flush()

    # -- close ------------------------------------------------------------------------------
    def metadata(self) -> Dict:
        """The ``rosbag2_bagfile_information`` mapping for what has been written so far."""
        start = self._start or 0
        duration = (self._end - self._start) if (self._start is not None and self._end is not None) else 0
        current_start = self._file_start or 0
        current = (self.mcap_path.name, current_start, (self._file_end or current_start) - current_start,
                   self._file_count)
        return md.bag_metadata(
            files=self._done_files + [current],
            topics=[(t.meta, t.count) for t in self._topics.values()],
            start_ns=start, duration_ns=duration, message_count=self.message_count,
            custom_data=self._custom_data, ros_distro=self._ros_distro)

    def close(self) -> Path:
        """Finish the MCAP file (metadata record, summary, footer), then write ``metadata.yaml``.

        Idempotent. Returns the bag directory.
        """
        with self._lock:
            if self.closed:
                return self.path
            info = self.metadata()
            self._finish_file()
            self.closed = True
        atomic_write(self.path / wk.METADATA_FILENAME, md.metadata_yaml(info))
        return self.path

    def _check_open(self) -> None:
        if self.closed:
            raise PearlError(f"{self.path}: bag is closed")

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def now_ns() -> int:
    """Wall-clock time in ns (the default log time of a recorder without sim time)."""
    return time.time_ns()
