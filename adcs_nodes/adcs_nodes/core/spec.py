"""The one spec language of every configurable value (DESIGN section 7): a :class:`Param`
(type, default, unit, range or choices, description, read-only) and a :class:`Section` (named
Params and sections, optionally with a selector key picking a variant: ``orbit.type``).

One validation path: :meth:`Param.validate` and :meth:`Section.validate` raise
:class:`SpecError` naming the key wherever a value enters (a scenario, ``--set``, a node
parameter, the plain engine's build). A section travels to a node as flat ROS parameters
(:meth:`Section.flatten`) and is read back through the same validation (:meth:`Section.read`).
Pure Python; no project imports.
"""
from __future__ import annotations

import array
import copy
import datetime
import difflib
import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union


#: Default of a value that must be given. A default of ``None``: optional, absent unless given.
REQUIRED = type('Required', (), {'__repr__': lambda self: 'required'})()

#: Value types. ``vec3``/``quat`` are fixed-length float lists (a quaternion of norm 1 within
#: 1e-3, returned normalised), ``matrix3`` 3 diagonal values, 9 row-major or a 3x3 list,
#: ``time`` ISO-8601 text (a YAML timestamp is accepted), ``table`` a list of records (each a
#: mapping of ``fields``), ``list``/``dict`` free YAML checked by ``check``.
TYPES = ('float', 'int', 'bool', 'str', 'time', 'float[]', 'str[]', 'vec3', 'quat', 'matrix3',
         'table', 'list', 'dict')
#: ROS parameter type of each value type (a table travels as one array per field; a list or
#: mapping is no node parameter).
ROS_TYPE = {'float': 'float', 'int': 'int', 'bool': 'bool', 'str': 'str', 'time': 'str',
            'float[]': 'float[]', 'str[]': 'str[]', 'vec3': 'float[]', 'quat': 'float[]',
            'matrix3': 'float[]'}
_WIDTH = {'vec3': 3, 'quat': 4, 'matrix3': 9}
_NOTES = {'quat': ', norm 1', 'matrix3': ', 3 diagonal or 9 row-major values',
          'time': ', an ISO 8601 date-time'}


def short(value: Any, limit: int = 80) -> str:
    """``repr(value)`` cut to ``limit`` characters (error messages never echo huge input)."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + '...'


def did_you_mean(key: Any, known: Sequence[str]) -> str:
    """`` (did you mean 'x'?)`` or ''."""
    near = difflib.get_close_matches(str(key), list(known), n=1)
    return f' (did you mean {near[0]!r}?)' if near else ''


def unknown_message(key: str, known: Sequence[str], where: str) -> str:
    """'unknown parameter X of WHERE (did you mean Y?); known: ...'."""
    return (f'unknown parameter {short(key, 60)} of {where}{did_you_mean(key, known)}; known: '
            f'{", ".join(sorted(known))}')


class SpecError(ValueError):
    """A value refused by its spec: ``key`` (dotted, relative to where it was checked), the
    reason ``why``, the spec's ``doc`` (meaning, unit, range) and the YAML ``line`` if known."""

    def __init__(self, key: str, why: str, doc: str = '', line: Optional[int] = None) -> None:
        super().__init__(f'{key}: {why}' if key else why)
        self.key, self.why, self.doc, self.line = key, why, doc, line

    def within(self, prefix: str, line: Optional[int] = None) -> 'SpecError':
        """The same error seen from the section ``prefix`` (its key prefixed)."""
        key = prefix + ('' if not self.key or self.key.startswith('[') else '.') + self.key
        return SpecError(key if prefix else self.key, self.why, self.doc,
                         self.line if self.line is not None else line)


def plain(value: Any) -> Any:
    """Plain dicts, lists and scalars of ``value`` (no line-number maps, tuples, numpy)."""
    if isinstance(value, Mapping):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if hasattr(value, 'tolist') and not isinstance(value, (str, bytes)):
        return plain(value.tolist())
    return value


def all_or_none(values: List[float]) -> List[float]:
    """A ``check``: every value > 0, or all zero (e.g. magnetorquer limits: none)."""
    if any(values) and not all(v > 0 for v in values):
        raise ValueError(f'must be all > 0 (or all zero: none), got {values}')
    return values


def iso_time(value: Any) -> str:
    """ISO-8601 date-time text of ``value`` (text, or a YAML timestamp: a ``datetime``);
    ``ValueError`` if it does not parse."""
    if isinstance(value, datetime.datetime):
        if value.tzinfo is not None:
            value = value.astimezone(datetime.timezone.utc).replace(tzinfo=None)
        return value.isoformat() + 'Z'
    if not isinstance(value, str):
        raise ValueError(f'expected ISO-8601 text, got {type(value).__name__}')
    try:
        datetime.datetime.fromisoformat(value.strip().replace('Z', '+00:00'))
    except ValueError:
        raise ValueError(f'{short(value)} is not an ISO-8601 date-time '
                         '(e.g. 2026-01-01T00:00:00Z)') from None
    return value


@dataclass(frozen=True)
class Param:
    """One typed value: ``name`` (the node parameter, the scenario key), ``type``
    (:data:`TYPES`), ``default`` (:data:`REQUIRED`; ``None``: optional), ``unit`` (``'-'``:
    none), one-line ``description``, inclusive ``min``/``max`` and ``positive`` (of each
    element of a list), ``choices`` of a text, ``length`` of a list, ``read_only`` (a change
    needs a restart), a table's record ``fields``, and ``check(value) -> value`` after the
    type and range checks (``ValueError``: a structured value's rules, a slew needs a
    duration, ...)."""

    name: str
    type: str
    default: Any
    unit: str = '-'
    description: str = ''
    min: Optional[float] = None
    max: Optional[float] = None
    positive: bool = False
    choices: Tuple[str, ...] = ()
    length: Optional[int] = None
    read_only: bool = False
    fields: Tuple['Param', ...] = ()
    check: Optional[Callable[[Any], Any]] = field(default=None, compare=False)

    def __post_init__(self) -> None:
        if self.type not in TYPES:
            raise ValueError(f'parameter {self.name}: unknown type {self.type!r}; known {TYPES}')
        if self.default is not REQUIRED and self.default is not None:
            self.validate(self.default)          # a default outside its own range is a bug

    required = property(lambda self: self.default is REQUIRED)

    # ---------------------------------------------------------------- validation
    def validate(self, value: Any) -> Any:
        """``value`` converted to this type, or :class:`SpecError` naming the parameter and
        why (type, range, choices, length; at most 80 characters of the value)."""
        try:
            return self.checked(value)
        except SpecError as exc:
            raise exc.within(self.name) from None

    def checked(self, value: Any) -> Any:
        """:meth:`validate`, the SpecError's key relative to this parameter ('' for itself)."""
        try:
            value = self._typed(value)
            return self.check(value) if self.check is not None else value
        except SpecError:
            raise
        except (ValueError, TypeError) as exc:
            raise SpecError('', str(exc), self.doc()) from None

    def _typed(self, value: Any) -> Any:
        t = self.type
        if t == 'float':
            return self._number(value)
        if t == 'int':
            if isinstance(value, bool) or not isinstance(value, int):
                raise ValueError(f'expected an integer, got {short(value)}')
            self._range(value)
            return int(value)
        if t == 'bool':
            if not isinstance(value, bool):
                raise ValueError(f'expected true or false, got {short(value)}')
            return value
        if t == 'str':
            return self._text(value)
        if t == 'time':
            return iso_time(value)
        if t == 'dict':
            if not isinstance(value, Mapping):
                raise ValueError(f'expected a mapping, got {short(value)}')
            return plain(value)
        if isinstance(value, (array.array, tuple)):
            value = list(value)
        if not isinstance(value, list):
            raise ValueError(f'expected a list, got {short(value)}')
        if t == 'table':
            return [self._record(i, item) for i, item in enumerate(value)]
        if t == 'list':
            return plain(value)
        if t == 'matrix3':
            return self._matrix(value)
        n = _WIDTH.get(t, self.length)
        if n is not None and len(value) != n:
            raise ValueError(f'expected {n} values, got {len(value)}')
        if t == 'str[]':
            return [self._text(v) for v in value]
        out = [self._number(v) for v in value]
        if t == 'quat':
            norm = math.sqrt(sum(c * c for c in out))
            if abs(norm - 1.0) > 1e-3:
                raise ValueError(f'quaternion norm is {norm:.6f}, expected 1')
            out = [c / norm for c in out]
        return out

    def _text(self, value: Any) -> str:
        if not isinstance(value, str):
            raise ValueError(f'expected text, got {short(value)}')
        if self.choices and value not in self.choices:
            raise ValueError(f'{short(value)} is not one of {", ".join(self.choices)}'
                             f'{did_you_mean(value, self.choices)}')
        return value

    def _number(self, value: Any) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f'expected a number, got {short(value)}')
        x = float(value)
        if not math.isfinite(x):
            raise ValueError(f'expected a finite number, got {short(value)}')
        self._range(x)
        return x

    def _range(self, x: float) -> None:
        unit = f' {self.unit}' if self.unit not in ('', '-') else ''
        if self.positive and not x > 0:
            raise ValueError(f'must be > 0{unit}, got {x:g}')
        if self.min is not None and x < self.min:
            raise ValueError(f'must be >= {self.min:g}{unit}, got {x:g}')
        if self.max is not None and x > self.max:
            raise ValueError(f'must be <= {self.max:g}{unit}, got {x:g}')

    def _matrix(self, value: List[Any]) -> List[List[float]]:
        if len(value) == 3 and not any(isinstance(v, (list, tuple)) for v in value):
            d = [self._number(v) for v in value]
            return [[d[0], 0.0, 0.0], [0.0, d[1], 0.0], [0.0, 0.0, d[2]]]
        if len(value) == 9 and not any(isinstance(v, (list, tuple)) for v in value):
            value = [value[0:3], value[3:6], value[6:9]]
        if len(value) == 3 and all(isinstance(v, (list, tuple)) and len(v) == 3
                                   for v in value):
            return [[self._number(v) for v in row] for row in value]
        raise ValueError(f'expected 3 numbers or a 3x3 matrix, got {short(value)}')

    def _record(self, i: int, item: Any) -> Dict[str, Any]:
        try:
            return Section('', self.fields).validate(item)
        except SpecError as exc:
            raise exc.within(f'[{i}]') from None

    # ---------------------------------------------------------------- documentation
    def range_text(self) -> str:
        """The range, the choices or the kind of value (``> 0, <= 1``, ``one of: a, b``,
        ``true or false``, ``text``, ``each >= 0, 3 values``), never empty."""
        t, n = ROS_TYPE.get(self.type, self.type), _WIDTH.get(self.type, self.length)
        count = f', {n} values' if n and self.type != 'matrix3' else ''
        if self.choices:
            return 'one of: ' + ', '.join(repr(c) if c == '' else c for c in self.choices)
        lo = '> 0' if self.positive else (f'>= {self.min:g}' if self.min is not None else '')
        rng = ', '.join(p for p in (lo, f'<= {self.max:g}' if self.max is not None else '')
                        if p)
        text = {'bool': 'true or false', 'str': 'text', 'str[]': 'list of text' + count,
                'int': rng or 'any integer', 'float': rng or 'any finite number',
                'float[]': (f'each {rng}' if rng else 'any finite numbers') + count}.get(t, t)
        return text + _NOTES.get(self.type, '')

    def doc(self) -> str:
        """What ``ros2 param describe`` and ``docs/scenarios.md`` say: the description,
        ``[unit]`` of a number (``[-]``: none), ``(range)``, ``(read-only: ...)``."""
        text = self.description.strip() or self.name
        if ROS_TYPE.get(self.type) in ('float', 'int', 'float[]'):
            text += f' [{self.unit or "-"}]'
        text += f' ({self.range_text()})'
        return text + (' (read-only: restart to change)' if self.read_only else '')

    def default_text(self) -> str:
        return {id(REQUIRED): 'required', id(None): 'optional'}.get(id(self.default),
                                                                    f'`{self.default}`')

    # ---------------------------------------------------------------- as ROS parameters
    def from_ros(self, value: Any) -> Any:
        """:meth:`validate` of a value as ROS hands it over (:meth:`coerce`)."""
        return self.validate(self.coerce(value))

    def coerce(self, value: Any) -> Any:
        """A value as ROS hands it over, typed as wanted: an integer for a float, integers in
        a float array, a tuple or ``array.array`` for a list, an untyped or byte-typed ``[]``
        (a parameter file's, the CLI's) for an empty array."""
        if isinstance(value, (tuple, array.array)):
            value = list(value)
        t = ROS_TYPE.get(self.type, '')
        if t.endswith('[]') and (value is None or value == [] or value == b''):
            value = []
        elif t == 'float' and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        elif t == 'float[]' and isinstance(value, list):
            value = [float(v) if isinstance(v, int) and not isinstance(v, bool) else v
                     for v in value]
        return value

    def ros(self, name: Optional[str] = None) -> 'Param':
        """This value as one ROS parameter (a ``vec3`` as a ``float[]`` of 3, ...)."""
        t = ROS_TYPE[self.type]
        length = _WIDTH.get(self.type, self.length) if self.type != 'matrix3' else None
        default = None if self.default in (REQUIRED, None) else self.flat_value(self.default)
        return Param(name or self.name, t, default, self.unit, self.description,
                     min=self.min, max=self.max, positive=self.positive,
                     choices=self.choices if t in ('str', 'str[]') else (),
                     length=length if t.endswith('[]') else None, read_only=self.read_only)

    def flat_value(self, value: Any) -> Any:
        """A validated value as its ROS parameter holds it (a 3x3 matrix as 9 row-major)."""
        if self.type == 'matrix3':
            return [v for row in self._matrix(list(value)) for v in row]
        return list(value) if isinstance(value, (list, tuple)) else value

    def columns(self, prefix: str, records: Sequence[Mapping[str, Any]] = ()
                ) -> Tuple['Param', ...]:
        """A table as ROS parameters: one array per field, ``<prefix><field>`` (defaults:
        the columns of ``records``)."""
        default = self.to_columns(records, prefix)
        out = []
        for f in self.fields:
            each = f', {_WIDTH[f.type]} values each' if f.type in _WIDTH else ''
            out.append(Param(prefix + f.name, 'str[]' if ROS_TYPE[f.type] == 'str' else
                             'float[]', default.get(prefix + f.name, []), f.unit,
                             f'{f.description} (one per {self.name} record{each})',
                             min=f.min, max=f.max, positive=f.positive, choices=f.choices,
                             read_only=self.read_only, check=_column(f)))
        return tuple(out)

    def to_columns(self, records: Sequence[Mapping[str, Any]], prefix: str) -> Dict[str, Any]:
        """Validated records as ``{<prefix><field>: array}`` (vectors concatenated)."""
        out = {}
        for f in self.fields:
            vals = [r[f.name] for r in records if r.get(f.name) is not None]
            if len(vals) == len(records):
                out[prefix + f.name] = [v for x in vals for v in (
                    f.flat_value(x) if f.type in _WIDTH else [x])]
        return out

    def from_columns(self, flat: Mapping[str, Any], prefix: str) -> List[Dict[str, Any]]:
        """The records of ``<prefix><field>`` arrays (to validate as the table); SpecError
        when the arrays give different numbers of records."""
        width = {f.name: _WIDTH.get(f.type, 1) for f in self.fields}
        cols = {k: list(flat[prefix + k]) for k in width if flat.get(prefix + k) is not None}
        n = max((len(v) // width[k] for k, v in cols.items()), default=0)
        for k, v in cols.items():
            if len(v) != n * width[k]:
                raise SpecError(prefix + k, f'{len(v)} values for {n} records ({width[k]} '
                                'per record)')
        return [{k: (v[i * width[k]:(i + 1) * width[k]] if width[k] > 1 else v[i])
                 for k, v in cols.items()} for i in range(n)]


def _column(field: Param) -> Callable[[List[Any]], List[Any]]:
    """The check of a table's field as a ROS array: each record's value as the field's."""
    width = _WIDTH.get(field.type, 1)

    def check(values: List[Any]) -> List[Any]:
        if len(values) % width:
            raise ValueError(f'expected {width} values per record, got {len(values)}')
        for i in range(0, len(values), width):
            field.checked(values[i:i + width] if width > 1 else values[i])
        return values
    return check


Spec = Union[Param, 'Section']


@dataclass(frozen=True, eq=False)
class Section:
    """A named group of Params and sections (a scenario section, a node's ``prefix.*``):
    ``params`` (with a ``selector``: every variant's, the selector among them), ``variants``
    (``{selector value: specs}``), ``optional`` (exists only when given; else filled with its
    defaults, or refused as missing with a required key or a selector), ``standalone`` (the
    required values of a node started alone) and ``check(values)``, a rule across its keys."""

    name: str
    params: Tuple[Spec, ...]
    description: str = ''
    optional: bool = False
    selector: str = ''
    variants: Mapping[str, Tuple[Spec, ...]] = field(default_factory=dict)
    standalone: Mapping[str, Any] = field(default_factory=dict)
    check: Optional[Callable[[Dict[str, Any]], Any]] = None

    def __getitem__(self, name: str) -> Spec:
        """The spec of key ``name`` (of the section, not of a variant)."""
        for p in self.params:
            if p.name == name:
                return p
        raise KeyError(name)

    def keys(self, data: Optional[Mapping[str, Any]] = None,
             line: Optional[int] = None) -> Dict[str, Spec]:
        """``{key: spec}`` of the section, of the variant ``data`` selects (SpecError on an
        unknown selector value)."""
        out = {p.name: p for p in self.params}
        if self.selector:
            sel = (data or {}).get(self.selector, out[self.selector].default)
            if not isinstance(sel, str) or sel not in self.variants:
                lines = getattr(data, 'lines', {})
                raise SpecError(self.selector, f'unknown {self.selector} {short(sel)}; '
                                f'allowed: {", ".join(self.variants)}', '',
                                lines.get(self.selector, line))
            out.update({p.name: p for p in self.variants[sel]})
        return out

    def required(self) -> bool:
        """A section that must be given: not optional, with a selector or a required key."""
        return not self.optional and (bool(self.selector) or any(
            isinstance(p, Param) and p.required for p in self.params))

    def validate(self, data: Any, line: Optional[int] = None) -> Dict[str, Any]:
        """The section's validated values, defaults filled in (:class:`SpecError` naming the
        key relative to the section, with the YAML line when ``data`` carries ``lines``)."""
        if data is None:
            data = {}
        if not isinstance(data, Mapping):
            raise SpecError('', f'expected a mapping, got {type(data).__name__}', '', line)
        lines = getattr(data, 'lines', {})
        specs = self.keys(data, line)
        for key in data:
            if key not in specs:
                raise SpecError(str(key), f'unknown key{did_you_mean(key, specs)}; allowed: '
                                f'{", ".join(sorted(specs))}', '', lines.get(key, line))
        out: Dict[str, Any] = {}
        for key, spec in specs.items():
            kline = lines.get(key, line)
            try:
                if isinstance(spec, Section):
                    if key not in data and spec.required():
                        raise SpecError('', 'missing required section')
                    if key in data or not spec.optional:
                        out[key] = spec.validate(data.get(key), kline)
                elif key in data:
                    out[key] = spec.checked(data[key])
                elif spec.required:
                    raise SpecError('', f'missing required key ({spec.doc()})')
                elif spec.default is not None:
                    out[key] = copy.deepcopy(spec.default)
            except SpecError as exc:
                raise exc.within(key, kline) from None
        if self.check is not None:
            try:
                self.check(out)
            except SpecError:
                raise
            except ValueError as exc:
                raise SpecError('', str(exc), '', line) from None
        return out

    # ---------------------------------------------------------------- as ROS parameters
    def flatten(self, values: Mapping[str, Any], prefix: str) -> Dict[str, Any]:
        """Validated section values as flat ROS parameters ``<prefix>.<key>`` (sub-sections
        nested, a table as one array per field ``<prefix>.<table>.<field>``)."""
        out: Dict[str, Any] = {}
        specs = self.keys(values)
        for key, value in values.items():
            spec, name = specs[key], f'{prefix}.{key}'
            if isinstance(spec, Section):
                out.update(spec.flatten(value, name))
            elif spec.type == 'table':
                out.update(spec.to_columns(value, name + '.'))
            else:
                out[name] = spec.flat_value(value)
        return out

    def read(self, flat: Mapping[str, Any], prefix: str) -> Dict[str, Any]:
        """The section from flat ROS parameters ``<prefix>.*`` (the inverse of
        :meth:`flatten`), validated as a scenario's; required keys a node started alone was
        not given come from :attr:`standalone`; an optional section none of whose keys is
        given is ``{}``. SpecError names the dotted key."""
        given = {k[len(prefix) + 1:]: v for k, v in flat.items()
                 if k.startswith(prefix + '.') and v is not None}
        if not given and self.optional:
            return {}
        try:
            data = self._nest(given, prefix)
            specs = self.keys(data)
            data.update({k: v for k, v in self.standalone.items()
                         if k in specs and k not in data})
            return self.validate(data)
        except SpecError as exc:
            raise exc.within(prefix) from None

    def defaults(self) -> Dict[str, Any]:
        """The values of a node started alone (no key given)."""
        return self.read({}, self.name)

    def _nest(self, given: Mapping[str, Any], prefix: str) -> Dict[str, Any]:
        out: Dict[str, Any] = {}
        specs = self.keys({k: v for k, v in given.items() if '.' not in k})
        groups: Dict[str, Dict[str, Any]] = {}
        for key, value in given.items():
            head, dot, tail = key.partition('.')
            spec = specs.get(head)
            if dot and (isinstance(spec, Section) or getattr(spec, 'type', '') == 'table'):
                groups.setdefault(head, {})[tail] = value
            elif dot or spec is None:
                names = [f'{prefix}.{n}' for n in self.flat_names()]
                raise SpecError(key, f'unknown parameter{did_you_mean(f"{prefix}.{key}", names)}'
                                f'; known: {", ".join(names)}')
            else:
                out[key] = value
        for head, sub in groups.items():
            spec = specs[head]
            try:
                if isinstance(spec, Section):
                    out[head] = spec._nest(sub, f'{prefix}.{head}')
                    continue
                unknown = sorted(set(sub) - {f.name for f in spec.fields})
                if unknown:
                    raise SpecError(unknown[0], 'unknown parameter; known: '
                                    f'{", ".join(f.name for f in spec.fields)}')
                out[head] = spec.from_columns(sub, '')
            except SpecError as exc:
                raise exc.within(head) from None
        return out

    def flat_names(self) -> List[str]:
        """Every flat parameter name of the section (relative; all variants)."""
        return sorted(name for name, _ in self.flat_params(''))

    def flat_params(self, prefix: str) -> List[Tuple[str, Param]]:
        """``(name, ROS Param)`` of every flat parameter of the section (all variants), for
        declarations and descriptors; ``prefix`` '' gives relative names."""
        specs = {p.name: p for p in self.params}
        for keys in self.variants.values():
            specs.update({p.name: p for p in keys})
        out = []
        for key, spec in specs.items():
            name = f'{prefix}.{key}' if prefix else key
            if isinstance(spec, Section):
                out += spec.flat_params(name)
            elif spec.type == 'table':
                out += [(c.name, c) for c in spec.columns(name + '.')]
            else:
                out.append((name, replace(spec.ros(name), read_only=True)))
        return out
