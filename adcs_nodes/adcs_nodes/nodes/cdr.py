"""Raw CDR endpoints of the nodes: publishers that send the generated codec's bytes and
``raw=True`` subscriptions that decode them (:mod:`adcs_nodes.msgs.cdr`; a typed rclpy hop
costs about 10x more CPU, DESIGN section 6). A type the generator does not cover, and a
payload that is not little-endian CDR, go through rclpy's serializer."""
from __future__ import annotations

import inspect
import os
import struct
from typing import Any, Callable, Optional

from adcs_nodes.msgs import cdr as _cdr
from adcs_nodes.msgs.cdr import Codec, Unsupported
from adcs_nodes.msgs.cdr import codec as generated_codec

#: Environment switch of the raw path: ``0``/``false``/``no``/``off`` turns it off (typed
#: publishes and takes); anything else (or unset) leaves it on.
ENV = 'ADCS_RAW_CDR'


def _rclpy_decode(data: bytes, msg_type: type) -> Any:
    from rclpy.serialization import deserialize_message
    return deserialize_message(data, msg_type)


_cdr.foreign_decoder = _rclpy_decode       # a big-endian payload: rclpy's deserializer


class RclpyCodec:
    """Fallback codec: rclpy's ``serialize_message`` / ``deserialize_message``."""

    generated = False

    def __init__(self, msg_type: type, why: str = '') -> None:
        from rclpy.serialization import deserialize_message, serialize_message
        self.msg_type = msg_type
        self.why = why
        self.encode: Callable[[Any], bytes] = serialize_message
        self.decode: Callable[[bytes], Any] = lambda data: deserialize_message(data, msg_type)


def codec(msg_type: type) -> Any:
    """The generated codec of ``msg_type``, or :class:`RclpyCodec` (``.why`` says why)."""
    try:
        return generated_codec(msg_type)
    except Unsupported as exc:
        return RclpyCodec(msg_type, str(exc))


def enabled() -> bool:
    """Whether raw endpoints are used (:data:`ENV`; read at endpoint creation)."""
    return os.environ.get(ENV, '').strip().lower() not in ('0', 'false', 'no', 'off')


def raw_codec(msg_type: type) -> Optional[Codec]:
    """The generated codec of ``msg_type`` when the raw path is on, else None (off, or a
    type the generator does not cover: that endpoint stays typed)."""
    if not enabled():
        return None
    c = codec(msg_type)
    return c if c.generated else None


def raw_publisher(pub: Any) -> Any:
    """Make ``pub.publish(msg)`` send ``codec.encode(msg)`` (rclpy's ``publish`` takes bytes
    and skips its conversion and serialization). A message of another class (or bytes) goes
    to the original ``publish`` unchanged; a lifecycle publisher keeps its check. No-op when
    the raw path is off or the type is not covered. Returns ``pub``; ``pub.raw_codec`` is the
    codec or None."""
    c = raw_codec(pub.msg_type)
    pub.raw_codec = c
    if c is None:
        return pub
    typed = pub.publish
    encode, cls = c.encode, c.msg_type

    def publish(msg: Any) -> None:
        typed(encode(msg) if type(msg) is cls else msg)

    pub.publish = publish
    return pub


def takes_info(callback: Callable) -> bool:
    """True when rclpy would call ``callback`` with the message info (two arguments), by
    the rule of rclpy's ``Subscription.callback`` setter."""
    try:
        inspect.signature(callback).bind(object())
        return False
    except TypeError:
        return True


#: What a malformed payload raises in a generated decoder.
DECODE_ERRORS = (struct.error, ValueError, IndexError, UnicodeDecodeError, TypeError,
                 RuntimeError)   # RuntimeError: rclpy's deserializer


def decoding(callback: Callable, c: Codec,
             on_error: Optional[Callable[[Exception], None]] = None) -> Callable:
    """A subscription callback for a ``raw=True`` subscription: bytes are decoded with ``c``
    and passed on as a message; a message object
    (the composed runner's in-process path) is passed on as it is. A callback that takes the
    message info (``publisher_guard.WithInfo``) gets it, from either executor's calling
    convention (``cb(msg, info)`` or ``cb((msg, info))``). A payload that does not decode is
    dropped: ``on_error(exc)`` is called, ``callback`` is not, nothing raises."""
    decode = c.decode

    def safe(data: Any) -> Any:
        if type(data) is not bytes:
            return data
        try:
            return decode(data)
        except DECODE_ERRORS as exc:
            if on_error is not None:
                on_error(exc)
            return None

    if not takes_info(callback):
        def cb(data: Any) -> None:
            msg = safe(data)
            if msg is not None:
                callback(msg)
        cb.raw_codec = c
        return cb
    from adcs_nodes.nodes.publisher_guard import WithInfo

    def fn(data: Any, info: Any) -> None:
        if type(data) is tuple:
            data, info = data
        msg = safe(data)
        if msg is not None:
            callback(msg, info)
    out = WithInfo(fn)
    out.raw_codec = c
    return out
