"""The one spec language of every configurable value: :class:`Param` (type, default, unit,
range or choices, description, read-only), validated the same way wherever the value enters
(scenario, node parameter, run-time change).

Pure Python; no rclpy.
"""
from __future__ import annotations

import array
import difflib
import math
from dataclasses import dataclass
from typing import Any, Optional, Sequence, Tuple


#: Parameter types: ROS parameter type names.
TYPES = ('float', 'int', 'bool', 'str', 'float[]', 'str[]')


def short(value: Any, limit: int = 80) -> str:
    """``repr(value)`` cut to ``limit`` characters (error messages never echo huge input)."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + '...'


@dataclass(frozen=True)
class Param:
    """One typed parameter of a registered component.

    Attributes
    ----------
    name : str
        Parameter name; the node parameter and the scenario key are both this name.
    type : str
        One of :data:`TYPES`.
    default : Any
        Default value (the only place it is written).
    unit : str
        Unit, e.g. ``'1/s'``, ``'A m^2'``, ``'-'`` for none.
    description : str
        One line.
    min, max : float or None
        Inclusive range of the value (of each element for arrays).
    positive : bool
        The value (each element) must be > 0.
    choices : tuple of str
        Allowed values of a ``str`` parameter.
    length : int or None
        Required length of an array.
    read_only : bool
        A change needs a restart (refused at run time).
    """

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

    def __post_init__(self) -> None:
        if self.type not in TYPES:
            raise ValueError(f'parameter {self.name}: unknown type {self.type!r}; known {TYPES}')
        self.validate(self.default)          # a default outside its own range is a bug

    # ---------------------------------------------------------------- validation
    def validate(self, value: Any) -> Any:
        """Return ``value`` converted to this parameter's type, or raise ``ValueError``.

        The message says why (type, range, choices, length), never echoing more than 80
        characters of the value. An array may come as a list, a tuple or an ``array.array``
        (what rclpy hands over for a ``double_array_value`` set at run time).
        """
        t = self.type
        if t == 'float':
            return self._number(value)
        if t == 'int':
            if isinstance(value, bool) or not isinstance(value, int):
                raise ValueError(f'{self.name}: expected an integer, got {short(value)}')
            self._range(value)
            return int(value)
        if t == 'bool':
            if not isinstance(value, bool):
                raise ValueError(f'{self.name}: expected true or false, got {short(value)}')
            return value
        if t == 'str':
            if not isinstance(value, str):
                raise ValueError(f'{self.name}: expected text, got {short(value)}')
            if self.choices and value not in self.choices:
                near = difflib.get_close_matches(value, self.choices, n=1)
                hint = f' (did you mean {near[0]!r}?)' if near else ''
                raise ValueError(f'{self.name}: {short(value)} is not one of '
                                 f'{", ".join(self.choices)}{hint}')
            return value
        if isinstance(value, array.array):
            value = value.tolist()
        if not isinstance(value, (list, tuple)):
            raise ValueError(f'{self.name}: expected a list, got {short(value)}')
        if self.length is not None and len(value) != self.length:
            raise ValueError(f'{self.name}: expected {self.length} values, got {len(value)}')
        if t == 'str[]':
            if not all(isinstance(v, str) for v in value):
                raise ValueError(f'{self.name}: expected a list of text, got {short(value)}')
            return list(value)
        return [self._number(v) for v in value]

    def _number(self, value: Any) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f'{self.name}: expected a number, got {short(value)}')
        x = float(value)
        if not math.isfinite(x):
            raise ValueError(f'{self.name}: expected a finite number, got {short(value)}')
        self._range(x)
        return x

    def _range(self, x: float) -> None:
        unit = f' {self.unit}' if self.unit not in ('', '-') else ''
        if self.positive and not x > 0:
            raise ValueError(f'{self.name}: must be > 0{unit}, got {x:g}')
        if self.min is not None and x < self.min:
            raise ValueError(f'{self.name}: must be >= {self.min:g}{unit}, got {x:g}')
        if self.max is not None and x > self.max:
            raise ValueError(f'{self.name}: must be <= {self.max:g}{unit}, got {x:g}')

    # ---------------------------------------------------------------- documentation
    def range_text(self) -> str:
        """Human range: ``> 0``, ``[0, 1]``, ``one of a, b``, or ''."""
        if self.choices:
            return 'one of ' + ', '.join(self.choices)
        lo = '> 0' if self.positive else (f'>= {self.min:g}' if self.min is not None else '')
        hi = f'<= {self.max:g}' if self.max is not None else ''
        return ', '.join(p for p in (lo, hi) if p)

    def doc(self) -> str:
        """Description with unit and range, for descriptors and docs."""
        extra = [f'[{self.unit}]'] if self.unit not in ('', '-') else []
        rng = self.range_text()
        if rng:
            extra.append(f'({rng})')
        if self.read_only:
            extra.append('(read-only: restart to change)')
        return ' '.join([self.description] + extra)


def unknown_message(key: str, known: Sequence[str], where: str) -> str:
    """'unknown parameter X of WHERE (did you mean Y?); known: ...'."""
    near = difflib.get_close_matches(str(key), list(known), n=1)
    hint = f' (did you mean {near[0]!r}?)' if near else ''
    return (f'unknown parameter {short(key, 60)} of {where}{hint}; known: '
            f'{", ".join(sorted(known))}')
