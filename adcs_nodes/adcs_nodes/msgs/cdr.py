"""CDR codecs of ROS 2 messages, generated once per type from the rosidl introspection.

:func:`codec` builds, once per message class, ``encode(msg) -> bytes`` and ``decode(bytes)
-> msg`` from ``SLOT_TYPES`` and ``__slots__``: a few ``struct`` calls instead of rclpy's
conversion and serialization, no rclpy (the plain engine's bags). The bytes are XCDR1 plain
CDR, little endian, with the encapsulation header ``00 01 00 00`` (primitives aligned to
their size, at most 8, from the end of the header; strings ``uint32 length`` + UTF-8 + NUL;
sequences ``uint32 count`` + elements, an empty one's elements not aligned, as Fast CDR
writes): what a typed publish sends (``rmw_fastrtps_cpp``), padding zeroed.
``serialize_message`` reports a length 4-16 bytes longer after an empty ``float64[]``, which
rosbags refuses. Tested against ``serialize_message``, rosbags and what DDS delivers
(``tests/node/test_cdr.py``, ``tests/node/test_raw_cdr.py``). Not covered
(:class:`Unsupported`; the nodes then use rclpy, :mod:`adcs_nodes.nodes.cdr`): ``wstring``,
``bool`` and ``byte`` arrays, a nested class that cannot be imported, a big-endian host.
Decoding fills a real message's slots with the field checks off (numeric sequences as
``array.array``, fixed arrays as ``numpy``); a value the encoder cannot pack raises
``struct.error``/``ValueError``, as the typed path would.
"""
from __future__ import annotations

import array
import struct
import sys
from typing import Any, Callable, Dict, List, NamedTuple, Optional, Tuple

import numpy as np
import rosidl_parser.definition as rdef

#: Encapsulation header of a little-endian plain CDR payload (XCDR1, options 0).
HEADER = b'\x00\x01\x00\x00'
#: ``(struct format, size, array typecode, numpy dtype)`` of each basic numeric type.
BASIC = {
    'double': ('d', 8, 'd', '<f8'), 'float': ('f', 4, 'f', '<f4'),
    'int8': ('b', 1, 'b', 'i1'), 'uint8': ('B', 1, 'B', 'u1'),
    'int16': ('h', 2, 'h', '<i2'), 'uint16': ('H', 2, 'H', '<u2'),
    'int32': ('i', 4, 'i', '<i4'), 'uint32': ('I', 4, 'I', '<u4'),
    'int64': ('q', 8, 'q', '<i8'), 'uint64': ('Q', 8, 'Q', '<u8'),
    'boolean': ('?', 1, None, None), 'octet': ('c', 1, None, None),
}
#: ``long double`` is 16 bytes in some IDL mappings: not covered.
_LITTLE = sys.byteorder == 'little'
_new = object.__new__


class Unsupported(TypeError):
    """A field type the generator does not cover (the nodes then use rclpy's serializer)."""


class Codec(NamedTuple):
    """The generated codec of a message class: ``encode(msg) -> bytes`` (CDR with the
    encapsulation header), ``decode(data) -> msg``, and their Python ``source``."""

    msg_type: type
    encode: Callable[[Any], bytes]
    decode: Callable[[bytes], Any]
    source: str
    generated: bool = True


# ---------------------------------------------------------------------- plan
def _slots(cls: type) -> List[str]:
    return [s for s in cls.__slots__ if s != '_check_fields']


def _basic(t) -> Tuple[str, int, Optional[str], Optional[str]]:
    name = t.typename
    if name not in BASIC:
        raise Unsupported(f'basic type {name!r}')
    return BASIC[name]


def _msg_class(t: 'rdef.NamespacedType') -> type:
    """The Python class of a nested type (``pkg.msg.Name``; an action's or a service's parts,
    ``Slew_Goal``, live in ``pkg.action._slew``)."""
    import importlib
    import re
    mod = importlib.import_module('.'.join(t.namespaces))
    if hasattr(mod, t.name):
        return getattr(mod, t.name)
    base = re.sub(r'(?<=[a-z0-9])(?=[A-Z])', '_', t.name.split('_')[0]).lower()
    try:
        return getattr(importlib.import_module(f'{mod.__name__}._{base}'), t.name)
    except (ImportError, AttributeError):
        raise Unsupported(f'class of {".".join(t.namespaces)}.{t.name} not found') from None


def _flatten(cls: type, path: Tuple[str, ...], out: List[tuple], nested: List[tuple]) -> None:
    """Leaves of ``cls`` (fields of nested messages inlined) in wire order.

    ``out`` gets ``(kind, path, *details)``; ``nested`` gets ``(path, class)`` of every
    nested message object to build when decoding (parents first)."""
    for slot, t in zip(_slots(cls), cls.SLOT_TYPES):
        p = path + (slot,)
        if isinstance(t, rdef.BasicType):
            fmt, size, _, _ = _basic(t)
            out.append(('prim', p, fmt, size))
        elif isinstance(t, rdef.AbstractWString):
            raise Unsupported('wstring')
        elif isinstance(t, rdef.AbstractString):
            out.append(('str', p))
        elif isinstance(t, rdef.NamespacedType):
            sub = _msg_class(t)
            nested.append((p, sub))
            _flatten(sub, p, out, nested)
        elif isinstance(t, (rdef.Array, rdef.AbstractSequence)):
            fixed = isinstance(t, rdef.Array)
            n = t.size if fixed else None
            vt = t.value_type
            if isinstance(vt, rdef.BasicType):
                fmt, size, code, dtype = _basic(vt)
                if code is None:
                    raise Unsupported(f'{vt.typename} array or sequence')
                out.append(('nums', p, fmt, size, code, dtype, n))
            elif isinstance(vt, rdef.AbstractWString):
                raise Unsupported('wstring array or sequence')
            elif isinstance(vt, rdef.AbstractString):
                out.append(('strs', p, n))
            elif isinstance(vt, rdef.NamespacedType):
                out.append(('msgs', p, _msg_class(vt), n))
            else:
                raise Unsupported(f'array of {vt!r}')
        else:
            raise Unsupported(f'field type {t!r}')


def _block_structs(prims: List[tuple]) -> List[struct.Struct]:
    """The 8 ``struct.Struct`` of a run of primitives, one per start offset mod 8 (the
    leading and inner padding as ``x`` bytes)."""
    out = []
    for start in range(8):
        fmt, off = '<', start
        for _, _, f, size in prims:
            pad = -off % size
            fmt += 'x' * pad + f
            off += pad + size
        out.append(struct.Struct(fmt))
    return out


# ---------------------------------------------------------------------- generation
def _count_encoder(n: Optional[int], field: str, what: str) -> List[str]:
    """Source lines writing a sequence's uint32 length (``n`` None) or checking a fixed
    array's length ``n``, for the list ``L`` of ``field``."""
    if n is None:
        return ['    q = -o & 3', '    parts.append(PAD[q] + U32.pack(len(L)))', '    o += q + 4']
    return [f'    if len(L) != {n}: raise ValueError("{field}: want {n} {what}")']


def _count_decoder(n: Optional[int]) -> List[str]:
    """Source lines reading a sequence's uint32 length into ``c`` (a fixed array: ``n``)."""
    if n is None:
        return ['    o += -o & 3', '    (c,) = U32.unpack_from(d, o)', '    o += 4']
    return [f'    c = {n}']


class _Gen:
    def __init__(self) -> None:
        self.env: Dict[str, Any] = {
            'array': array.array, 'np': np, 'U32': struct.Struct('<I'), 'HEADER': HEADER,
            '_new': _new, 'PAD': [b'\x00' * i for i in range(8)], 'nums': _nums,
            'strip': _strip, 'MV': memoryview, 'frombuffer': np.frombuffer}
        self.n = 0
        self.bodies: Dict[type, Tuple[str, str]] = {}
        self.lines: List[str] = []

    def name(self, prefix: str, value: Any) -> str:
        self.n += 1
        key = f'{prefix}{self.n}'
        self.env[key] = value
        return key

    def body(self, cls: type) -> Tuple[str, str]:
        """Names of the generated ``enc_X(m, parts, o) -> o`` and ``dec_X(d, o) -> (m, o)``
        of ``cls`` (generated on first use; the source goes to ``self.lines``)."""
        if cls in self.bodies:
            return self.bodies[cls]
        ops: List[tuple] = []
        nested: List[tuple] = []
        _flatten(cls, (), ops, nested)
        self.n += 1
        enc, dec = f'enc_{cls.__name__}_{self.n}', f'dec_{cls.__name__}_{self.n}'
        self.bodies[cls] = (enc, dec)
        self.env[f'C_{dec}'] = cls
        e = [f'def {enc}(m, parts, o):']
        d = [f'def {dec}(d, o):', f'    m = _new(C_{dec})', '    m._check_fields = False']
        for p, sub in nested:
            k = self.name('C', sub)
            var = _var(p)
            d += [f'    {var} = _new({k})', f'    {var}._check_fields = False',
                  f'    {_var(p[:-1])}.{p[-1]} = {var}']
        i = 0
        while i < len(ops):
            kind = ops[i][0]
            if kind == 'prim':
                j = i
                while j < len(ops) and ops[j][0] == 'prim':
                    j += 1
                self._prims(ops[i:j], e, d)
                i = j
                continue
            getattr(self, '_' + kind)(ops[i], e, d)
            i += 1
        e += ['    return o']
        d += ['    return m, o']
        self.lines += e + [''] + d + ['']
        return enc, dec

    def _prims(self, run: List[tuple], e: List[str], d: List[str]) -> None:
        """A run of primitives: one ``struct`` (chosen by the start offset mod 8)."""
        k = self.name('B', _block_structs(run))
        args = ', '.join(_ref(r[1]) for r in run)
        e += [f'    S = {k}[o & 7]', f'    parts.append(S.pack({args}))', '    o += S.size']
        targets = ', '.join(_dref(r[1]) for r in run)
        d += [f'    S = {k}[o & 7]', f'    ({targets},) = S.unpack_from(d, o)',
              '    o += S.size']

    def _str(self, op: tuple, e: List[str], d: List[str]) -> None:
        p = op[1]
        e += [f'    s = {_ref(p)}.encode()', "    if b'\\0' in s: s = strip(s)",
              '    n = len(s) + 1', '    q = -o & 3',
              "    parts.append(PAD[q] + U32.pack(n) + s + b'\\0')", '    o += q + 4 + n']
        d += ['    o += -o & 3', '    (n,) = U32.unpack_from(d, o)',
              f"    {_dref(p)} = str(d[o + 4:o + 3 + n], 'utf-8')", '    o += 4 + n']

    def _nums(self, op: tuple, e: List[str], d: List[str]) -> None:
        _, p, fmt, size, code, dtype, n = op
        al = min(size, 8)
        if n is None:      # sequence: count, then the elements aligned
            e += [f'    v = nums({_ref(p)}, {code!r})', '    q = -o & 3',
                  f'    c = len(v) // {size}', '    o += q + 4',
                  f'    r = -o & {al - 1} if c else 0' if al > 1 else '    r = 0',
                  '    parts.append(PAD[q] + U32.pack(c) + PAD[r] + v)', '    o += r + len(v)']
            d += ['    o += -o & 3', '    (c,) = U32.unpack_from(d, o)', '    o += 4']
            if al > 1:
                d += [f'    if c: o += -o & {al - 1}']
            d += [f'    a = array({code!r})', f'    a.frombytes(d[o:o + c * {size}])',
                  f'    {_dref(p)} = a', f'    o += c * {size}']
            return
        e += [f'    v = nums({_ref(p)}, {code!r}, {n})',      # fixed array: aligned elements
              f'    r = -o & {al - 1}' if al > 1 else '    r = 0',
              '    parts.append(PAD[r] + v)', '    o += r + len(v)']
        if al > 1:
            d += [f'    o += -o & {al - 1}']
        d += [f"    {_dref(p)} = frombuffer(d, {dtype!r}, {n}, o).astype("
              f"{dtype[-2:].lstrip('<')!r})", f'    o += {n * size}']

    def _strs(self, op: tuple, e: List[str], d: List[str]) -> None:
        p, n = op[1], op[2]
        e += [f'    L = {_ref(p)}'] + _count_encoder(n, p[-1], 'strings')
        e += ['    for s in L:', '        s = s.encode()', "        if b'\\0' in s: s = strip(s)",
              '        k = len(s) + 1', '        q = -o & 3',
              "        parts.append(PAD[q] + U32.pack(k) + s + b'\\0')", '        o += q + 4 + k']
        d += _count_decoder(n)
        d += ['    L = []', '    for _ in range(c):', '        o += -o & 3',
              '        (k,) = U32.unpack_from(d, o)',
              "        L.append(str(d[o + 4:o + 3 + k], 'utf-8'))", '        o += 4 + k',
              f'    {_dref(p)} = L']

    def _msgs(self, op: tuple, e: List[str], d: List[str]) -> None:
        p, sub, n = op[1], op[2], op[3]
        se, sd = self.body(sub)
        e += [f'    L = {_ref(p)}'] + _count_encoder(n, p[-1], 'items')
        e += ['    for x in L:', f'        o = {se}(x, parts, o)']
        d += _count_decoder(n)
        d += ['    L = []', '    for _ in range(c):', f'        x, o = {sd}(d, o)',
              '        L.append(x)', f'    {_dref(p)} = L']


def _var(p: Tuple[str, ...]) -> str:
    """Decoder variable of the nested message at path ``p`` (``m``: the message itself)."""
    return 'm_' + '_'.join(x.lstrip('_') for x in p) if p else 'm'


def _ref(p: Tuple[str, ...]) -> str:
    return 'm.' + '.'.join(p)


def _dref(p: Tuple[str, ...]) -> str:
    return f'{_var(p[:-1])}.{p[-1]}'


def _strip(s: bytes) -> bytes:
    """UTF-8 bytes cut at the first NUL (rclpy's C string conversion stops there)."""
    return s.split(b'\0', 1)[0]


def _nums(v: Any, code: str, n: Optional[int] = None) -> bytes:
    """Little-endian bytes of a numeric sequence or fixed array (``array.array``, numpy
    array or any sequence of numbers); ``n``: the fixed length (ValueError if it differs)."""
    if type(v) is array.array and v.typecode == code:
        b = v.tobytes()
    elif isinstance(v, np.ndarray):
        b = np.ascontiguousarray(v, dtype=np.dtype(code).newbyteorder('<')).tobytes()
    else:
        b = array.array(code, v).tobytes()
    if n is not None and len(b) != n * array.array(code).itemsize:
        raise ValueError(f'fixed array of {n} elements, got {len(v)}')
    return b


_CACHE: Dict[type, Any] = {}


def codec(msg_type: type) -> 'Codec':
    """The generated codec of ``msg_type`` (cached); :class:`Unsupported` when a field type
    is not covered or the host is big-endian (``str(exc)`` says which)."""
    got = _CACHE.get(msg_type)
    if got is None:
        if not _LITTLE:
            got = Unsupported('big-endian host')
        else:
            try:
                got = _generate(msg_type)
            except Unsupported as exc:
                got = exc
        _CACHE[msg_type] = got
    if isinstance(got, Unsupported):
        raise got
    return got


#: ``decode(data, msg_type)`` of a payload that is not little-endian CDR (the nodes set
#: rclpy's deserializer: :mod:`adcs_nodes.nodes.cdr`); None: ``ValueError``.
foreign_decoder: Optional[Callable[[bytes, type], Any]] = None


def _not_le(data: bytes, msg_type: type) -> Any:
    if foreign_decoder is not None:
        return foreign_decoder(data, msg_type)
    raise ValueError(f'{msg_type.__name__}: not little-endian CDR (representation '
                     f'{bytes(data[:2]).hex()})')


def _generate(msg_type: type) -> Codec:
    g = _Gen()
    enc, dec = g.body(msg_type)
    g.env['not_le'] = _not_le
    g.env['T'] = msg_type
    g.lines += [
        'def encode(m):',
        '    parts = [HEADER]',
        f'    {enc}(m, parts, 0)',
        "    return b''.join(parts)",
        '',
        'def decode(data):',
        '    if data[1] != 1:',
        '        return not_le(data, T)',
        f'    return {dec}(MV(data)[4:], 0)[0]',
        '']
    source = '\n'.join(g.lines)
    exec(compile(source, f'<cdr {msg_type.__module__}.{msg_type.__name__}>', 'exec'), g.env)
    return Codec(msg_type, g.env['encode'], g.env['decode'], source)
