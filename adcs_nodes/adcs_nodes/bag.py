"""rosbag2 (MCAP) helpers on ``rosbags``: the typestore, reading with clear errors, recovery
of an unfinished MCAP file, the flat view of a message. No rclpy, no generated messages."""
from __future__ import annotations

import dataclasses
import os
import struct
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any, Dict, Iterable, Iterator, List, Optional, Tuple

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness, QosReliability,
                                QosTime)
from rosbags.typesys import Stores, TypesysError, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

ADCS_PACKAGE = 'adcs_msgs'
#: rosbag2 metadata version of the bags the recorder and the plain engine write.
BAG_VERSION = 8

#: A message whose first field has one of these types is stamped.
_STAMP_FIELD_TYPES = {
    'std_msgs/msg/Header': True,          # stamp inside the header
    'builtin_interfaces/msg/Time': False,  # the field itself is the stamp (rosgraph_msgs/Clock)
}

#: Topics the graph publishes latched (transient local); the others are reliable, volatile.
LATCHED_TOPICS = ('/tf_static', '/adcs/controller_status', '/lockstep/ready')
_INFINITE = QosTime(9223372036, 854775807)      # rmw's "infinite", as the graph reports it


def offered_qos(topic: str) -> List[Qos]:
    """``offered_qos_profiles`` of resolved ``topic`` as the recorder stores the graph's."""
    latched = topic in LATCHED_TOPICS
    return [Qos(history=QosHistory.UNKNOWN, depth=0, reliability=QosReliability.RELIABLE,
                durability=QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE,
                deadline=_INFINITE, lifespan=_INFINITE, liveliness=QosLiveliness.AUTOMATIC,
                liveliness_lease_duration=_INFINITE, avoid_ros_namespace_conventions=False)]


_PREFERRED_STORES = ('ros2_kilted', 'ros2_jazzy')


def _store_for_distro() -> Stores:
    """Typestore of ``$ROS_DISTRO`` when rosbags has it, else the newest of Kilted / Jazzy."""
    distro = os.environ.get('ROS_DISTRO', '').strip().lower()
    names = ([f'ros2_{distro}'] if distro else []) + list(_PREFERRED_STORES)
    for name in names:
        try:
            return Stores(name)
        except ValueError:
            continue
    return Stores.LATEST


def _share_msg_dir(package: str) -> Optional[Path]:
    """``share/<package>/msg`` found through the ament index, or ``None``."""
    try:
        from ament_index_python.packages import (PackageNotFoundError,
                                                 get_package_share_directory)
    except ImportError:
        return None
    try:
        path = Path(get_package_share_directory(package)) / 'msg'
    except (PackageNotFoundError, ValueError, LookupError, OSError):
        return None
    return path if path.is_dir() else None


def adcs_msg_dir() -> Path:
    """The ``adcs_msgs`` ``.msg`` directory: installed, else the source tree."""
    share = _share_msg_dir(ADCS_PACKAGE)
    if share is not None and any(share.glob('*.msg')):
        return share
    source = Path(__file__).resolve().parents[2] / ADCS_PACKAGE / 'msg'
    if source.is_dir() and any(source.glob('*.msg')):
        return source
    raise FileNotFoundError(
        f'cannot find the {ADCS_PACKAGE} .msg files (not installed, and no {source})')


def make_typestore() -> Typestore:
    """A typestore: the standard types of ``$ROS_DISTRO`` (else Kilted) plus ``adcs_msgs``."""
    store = get_typestore(_store_for_distro())
    types: Dict[str, Any] = {}
    for path in sorted(adcs_msg_dir().glob('*.msg')):
        types.update(get_types_from_msg(path.read_text(), f'{ADCS_PACKAGE}/msg/{path.stem}'))
    store.register(types)
    return store


def _referenced_types(fielddef: Any) -> Iterator[str]:
    """Names of the message types referenced by one rosbags field descriptor."""
    node, arg = fielddef
    if getattr(node, 'name', '') == 'NAME':
        yield arg
    elif getattr(node, 'name', '') in ('ARRAY', 'SEQUENCE'):
        yield from _referenced_types(arg[0])


def ensure_type(store: Typestore, msgtype: str) -> bool:
    """Load ``msgtype`` and what it references into ``store``; False: no definition found."""
    if msgtype in store.fielddefs:
        return True
    parts = msgtype.split('/')
    if len(parts) != 3 or parts[1] != 'msg':
        return False
    pkg, _, name = parts
    msg_dir = _share_msg_dir(pkg)
    if msg_dir is None and pkg == ADCS_PACKAGE:
        msg_dir = adcs_msg_dir()
    path = msg_dir / f'{name}.msg' if msg_dir is not None else None
    if path is None or not path.is_file():
        return False
    try:
        types = get_types_from_msg(path.read_text(), msgtype)
        store.register(types)
    except TypesysError:
        return False
    for _, fields in types.values():
        for _, fielddef in fields:
            for dep in _referenced_types(fielddef):
                if not ensure_type(store, dep):
                    return False
    return True


def stamp_kind(store: Typestore, msgtype: str) -> Optional[str]:
    """How ``msgtype`` carries its stamp: ``'header'``, ``'time'`` (``Clock``) or None."""
    fielddef = store.fielddefs.get(msgtype)
    if not fielddef or not fielddef[1]:
        return None
    _, (node, arg) = fielddef[1][0]
    if getattr(node, 'name', '') == 'NAME' and arg in _STAMP_FIELD_TYPES:
        return 'header' if _STAMP_FIELD_TYPES[arg] else 'time'
    return None


def stamp_offset(store: Typestore, msgtype: str) -> Optional[int]:
    """Byte offset of the stamp a CDR message of ``msgtype`` is logged at: 4 (it opens the
    payload), 8 (``TFMessage``: the first element's ``header.stamp``) or None."""
    if stamp_kind(store, msgtype) is not None:
        return 4
    fields = (store.fielddefs.get(msgtype) or (None, ()))[1]
    if not fields:
        return None
    node, arg = fields[0][1]
    if getattr(node, 'name', '') != 'SEQUENCE' or getattr(arg[0][0], 'name', '') != 'NAME':
        return None
    return 8 if stamp_kind(store, arg[0][1]) == 'header' else None


def cdr_stamp_ns(raw: bytes, offset: int = 4) -> Optional[int]:
    """Stamp [ns] at ``offset`` of a CDR message; None: too short, or an empty sequence."""
    if len(raw) < offset + 8:
        return None
    order = '<' if raw[1] & 0x01 else '>'
    if offset == 8 and struct.unpack_from(order + 'I', raw, 4)[0] == 0:
        return None
    sec, nanosec = struct.unpack_from(order + 'iI', raw, offset)
    return sec * 1_000_000_000 + nanosec


def header_stamp_ns(msg: Any) -> Optional[int]:
    """``header.stamp`` (or the ``clock`` of ``rosgraph_msgs/Clock``) in ns, else ``None``."""
    stamp = getattr(getattr(msg, 'header', None), 'stamp', None)
    if stamp is None:
        stamp = getattr(msg, 'clock', None)
    if stamp is None or not hasattr(stamp, 'nanosec'):
        return None
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _is_message(value: Any) -> bool:
    return dataclasses.is_dataclass(value) and not isinstance(value, type)


def _message_fields(msg: Any) -> Iterator[Tuple[str, Any]]:
    for field in dataclasses.fields(msg):
        name = field.name
        if name.startswith('__') or name == 'structure_needs_at_least_one_member':
            continue
        yield name, getattr(msg, name)


def _scalar(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    return value


def flatten_message(msg: Any, prefix: str = '') -> List[Tuple[str, Any]]:
    """A deserialised message as ``(dotted_name, scalar)`` pairs (``poses[2].position.x``)."""
    out: List[Tuple[str, Any]] = []
    for name, value in _message_fields(msg):
        key = f'{prefix}{name}'
        _flatten_value(key, value, out)
    return out


def _flatten_value(key: str, value: Any, out: List[Tuple[str, Any]]) -> None:
    if _is_message(value):
        out.extend(flatten_message(value, f'{key}.'))
    elif isinstance(value, (np.ndarray, list, tuple, bytes, bytearray)):
        for i, item in enumerate(value):
            _flatten_value(f'{key}[{i}]', item, out)
    else:
        out.append((key, _scalar(value)))


# ---------------------------------------------------------------------- crash safety
#: MCAP file magic (start and end of a finished file).
MCAP_MAGIC = b'\x89MCAP0\r\n'


def flush_writer(writer: Any, fsync: bool = False) -> bool:
    """Flush the pending MCAP chunk of a rosbags 0.11 ``Writer``; whether one was written."""
    storage = getattr(writer, 'storage', None)
    chunk = getattr(storage, 'chunk', None)
    bio = getattr(storage, 'bio', None)
    if chunk is None or bio is None or not hasattr(storage, 'close_chunk'):
        return False
    wrote = bool(chunk.msgs)  # schemas / channels alone wait for their first message
    if wrote:
        storage.close_chunk()
    bio.flush()
    if fsync:
        os.fsync(bio.fileno())
    return wrote


class _Bounded:
    """Read-only view of the first ``limit`` bytes of a binary file (for the stream reader)."""

    def __init__(self, fh, limit: int) -> None:
        self._fh, self._left = fh, limit

    def read(self, n: int = -1) -> bytes:
        n = self._left if n is None or n < 0 else min(n, self._left)
        data = self._fh.read(n)
        self._left -= len(data)
        return data


def _complete_records_end(fh, size: int) -> int:
    """Offset just after the last complete top-level MCAP record of an open file (0: none)."""
    fh.seek(0)
    if fh.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
        return 0
    pos = good = len(MCAP_MAGIC)
    while pos + 9 <= size:
        fh.seek(pos)
        head = fh.read(9)
        if len(head) < 9:
            break
        opcode, length = struct.unpack('<BQ', head)
        end = pos + 9 + length
        if opcode == 0 or end > size:
            break  # zero bytes of a file extended but never written, or a cut record
        if pos == len(MCAP_MAGIC) and opcode != 0x01:
            break  # an MCAP file starts with its header record
        pos = good = end
        if opcode == 0x02:  # footer: the closing magic follows
            break
    return good


def recover_mcap(src: os.PathLike | str, dst: os.PathLike | str) -> Tuple[int, int]:
    """Copy every complete record of an unfinished MCAP file into a finished one ``dst``;
    ``(messages recovered, bytes lost)``. ``ValueError``: not MCAP, or a corrupt record."""
    from mcap.exceptions import EndOfFile, McapError
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader
    from mcap.writer import CompressionType
    from mcap.writer import Writer as McapStreamWriter

    size = os.path.getsize(src)
    count = 0
    with open(src, 'rb') as fh, open(dst, 'wb') as out:
        good = _complete_records_end(fh, size)
        if good <= len(MCAP_MAGIC):
            raise ValueError(f'{src}: empty file (the recorder wrote nothing)' if not size else
                             f'{src}: not an MCAP file (wrong magic, or no complete header '
                             'record)')
        fh.seek(0)
        writer = McapStreamWriter(out, compression=CompressionType.NONE)
        writer.start(profile='ros2', library='adcs recover_mcap')
        schemas: Dict[int, int] = {}
        channels: Dict[int, int] = {}
        try:
            for rec in StreamReader(_Bounded(fh, good)).records:
                if isinstance(rec, Schema) and rec.id not in schemas:
                    schemas[rec.id] = writer.register_schema(rec.name, rec.encoding, rec.data)
                elif isinstance(rec, Channel) and rec.id not in channels:
                    channels[rec.id] = writer.register_channel(
                        rec.topic, rec.message_encoding, schemas.get(rec.schema_id, 0),
                        dict(rec.metadata))
                elif isinstance(rec, Message) and rec.channel_id in channels:
                    writer.add_message(channels[rec.channel_id], rec.log_time, rec.data,
                                       rec.publish_time, rec.sequence)
                    count += 1
        except EndOfFile:
            pass  # the end of the complete records
        except (McapError, struct.error, UnicodeDecodeError, ValueError) as exc:
            raise ValueError(f'{src}: corrupt MCAP record: {exc}') from exc
        writer.finish()
    return count, size - good


def _mcap_finished(path: Path) -> bool:
    """Whether an MCAP file ends with the closing magic (cheap check, no parsing)."""
    try:
        with open(path, 'rb') as fh:
            fh.seek(0, os.SEEK_END)
            if fh.tell() < 2 * len(MCAP_MAGIC):
                return False
            fh.seek(-len(MCAP_MAGIC), os.SEEK_END)
            return fh.read() == MCAP_MAGIC
    except OSError:
        return False


def _mcap_of(path: Path) -> Optional[Path]:
    """The MCAP file of a bag path (the file itself, or a directory's single ``.mcap``)."""
    if path.is_file():
        return path if path.suffix == '.mcap' else None
    mcaps = sorted(path.glob('*.mcap'))
    return mcaps[0] if len(mcaps) == 1 else None


def _resolve(bag_path: os.PathLike | str) -> Path:
    """Path handed to rosbags: the bag directory, or its single ``.mcap`` if metadata is gone."""
    path = Path(bag_path)
    if not path.exists():
        raise FileNotFoundError(f'bag not found: {path}')
    if path.is_dir() and not (path / 'metadata.yaml').exists():
        mcaps = sorted(path.glob('*.mcap'))
        if len(mcaps) != 1:
            raise ValueError(f'{path}: not a rosbag2 bag (no metadata.yaml and '
                             f'{len(mcaps)} .mcap files)')
        return mcaps[0]
    return path


@contextmanager
def open_bag(bag_path: os.PathLike | str) -> Iterator[AnyReader]:
    """A bag (directory or ``.mcap``) as an open ``AnyReader``; an unfinished one through
    :func:`recover_mcap`, with a warning. ``FileNotFoundError``, ``ValueError`` naming it."""
    path = _resolve(bag_path)
    with ExitStack() as stack:
        mcap = _mcap_of(path)
        if mcap is not None and not _mcap_finished(mcap):
            path = _recovered(stack, mcap, bag_path)
        try:
            reader = AnyReader([path], default_typestore=make_typestore())
            reader.open()
        except FileNotFoundError:
            raise
        except Exception as exc:  # rosbags raises several unrelated error types for bad files
            raise ValueError(f'{bag_path}: cannot read bag: {exc}') from exc
        try:
            yield reader
        finally:
            try:
                reader.close()
            except Exception:  # noqa: BLE001 - closing a broken reader must not mask the error
                pass


#: Bags already reported as unfinished in this process (one warning per bag).
_WARNED: set = set()


def _recovered(stack: ExitStack, mcap: Path, bag_path: os.PathLike | str) -> Path:
    """Recover an unfinished MCAP file into a temporary directory removed by ``stack``."""
    import logging
    import tempfile

    tmp = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix='adcs-recover-')))
    out = tmp / mcap.name
    try:
        count, lost = recover_mcap(mcap, out)
    except OSError as exc:
        raise ValueError(f'{bag_path}: unfinished bag, recovery failed: {exc}') from exc
    if str(bag_path) in _WARNED:
        return out
    _WARNED.add(str(bag_path))
    logging.getLogger(__name__).warning(
        '%s: unfinished bag (recorder killed or disk full?): read %d messages from its '
        'complete records%s', bag_path, count,
        f'; the last {lost} bytes are a cut record' if lost else '')
    return out


def read_messages(bag_path: os.PathLike | str, topics: Optional[Iterable[str]] = None
                  ) -> Iterator[Tuple[str, int, Any]]:
    """``(topic, log_time_ns, message)`` of ``topics`` (None: all) in log-time order."""
    wanted = None if topics is None else set(topics)
    stack = ExitStack()
    reader = stack.enter_context(open_bag(bag_path))  # errors raise here, not on first next()
    return _iterate(stack, reader, wanted, bag_path)


def _iterate(stack: ExitStack, reader: AnyReader, wanted: Optional[set],
             bag_path: os.PathLike | str) -> Iterator[Tuple[str, int, Any]]:
    with stack:
        conns = [c for c in reader.connections if wanted is None or c.topic in wanted]
        for conn, t_ns, raw in raw_messages(reader, conns, bag_path):
            yield conn.topic, t_ns, reader.deserialize(raw, conn.msgtype)


def raw_messages(reader: AnyReader, conns: list, bag_path: os.PathLike | str) -> Iterator:
    """``reader.messages`` of ``conns``; a failure: ``ValueError`` naming the bag."""
    if not conns:
        return
    try:
        yield from reader.messages(connections=conns)
    except Exception as exc:
        raise ValueError(f'{bag_path}: corrupt bag: {exc}') from exc


def stamped_messages(bag_path: os.PathLike | str, topics: Iterable[str],
                     untimed: Iterable[str] = (), decode: Iterable[str] = (),
                     header_only: bool = False) -> Iterator[Tuple[str, int, bytes, Any]]:
    """``(topic, stamp_ns, raw CDR, message)`` of ``topics`` in recording order (stamp 0 for
    ``untimed`` ones, ``message`` for ``decode`` ones); ``ValueError``: a topic unstamped."""
    untimed, decode = set(untimed), set(decode)
    need = ('header',) if header_only else ('header', 'time')
    with open_bag(bag_path) as reader:
        conns = [c for c in reader.connections if c.topic in set(topics)]
        for c in conns:
            if c.topic not in untimed and stamp_kind(reader.typestore, c.msgtype) not in need:
                raise ValueError(f'{c.topic} [{c.msgtype}] has no '
                                 + ('header.stamp' if header_only else 'time stamp'))
        for conn, _, raw in raw_messages(reader, conns, bag_path):
            raw = bytes(raw)
            stamp = 0 if conn.topic in untimed else cdr_stamp_ns(raw)
            if stamp is None:
                raise ValueError(f'unreadable message on {conn.topic}')
            yield conn.topic, stamp, raw, (reader.deserialize(raw, conn.msgtype)
                                           if conn.topic in decode else None)


def list_topics(bag_path: os.PathLike | str) -> Dict[str, str]:
    """``{topic: msgtype}`` of the bag's connections (no message is read)."""
    with open_bag(bag_path) as reader:
        return {c.topic: c.msgtype for c in sorted(reader.connections, key=lambda c: c.topic)}
