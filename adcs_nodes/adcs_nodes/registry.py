"""The registry: every controller, estimator algorithm and sensor model, declared once.

An :class:`Entry` names a component, its core class, a typed parameter spec (:class:`Param`:
type, default, unit, range or choices, description, read-only), the inputs it needs and the
actuators it commands. Everything else is generated from it, with no per-name code anywhere
else (compare ros2_controllers' generated parameters and pluginlib registration):

* node parameter declarations with ``ParameterDescriptor``s, unknown-parameter refusal and the
  run-time set-parameters validation (:mod:`adcs_nodes.nodes.params`);
* the scenario schema, its validation and ``docs/scenarios.md`` (:mod:`adcs_nodes.tools.scenario`);
* the graph builder's nodes and topics (:mod:`adcs_nodes.tools.graph`);
* ``adcs list`` and ``adcs schema``.

Built-in entries live in :mod:`adcs_nodes.entries` (controllers, estimators) and
``sim_node.entries`` (sensor models; loaded when the simulator is installed, the flight
software never imports it). More come from plugins: a module or ``.py`` file named in a
scenario's ``plugins`` list (or the node parameter ``plugins``), or an installed package's
entry point in group ``adcs.registry``. A plugin module calls :func:`register`.

Pure Python; no rclpy.
"""
from __future__ import annotations

import array
import difflib
import importlib
import importlib.util
import math
import os
import sys
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, Tuple

from adcs_nodes import inputs as _inputs

KINDS = ('controller', 'estimator', 'sensor', 'fault')

#: What a controller may read or an estimator may take: the input records' names
#: (:mod:`adcs_nodes.inputs`: topic, type, providing sensor, period parameter).
INPUTS = _inputs.NAMES
#: What a controller may command.
ACTUATORS = ('magnetorquer', 'wheels', 'torque')

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


@dataclass(frozen=True)
class Entry:
    """One registered component.

    Attributes
    ----------
    kind : str
        ``'controller'``, ``'estimator'``, ``'sensor'`` or ``'fault'`` (a fault kind of the world).
    name : str
        Unique within its kind (scenario key, node-name stem, topic segment).
    description : str
        One line, shown by ``adcs list``.
    core : str
        ``'module:Class'`` of the core class (imported only when built).
    params : tuple of Param
        The component's own parameters.
    build : callable
        ``build(params, context) -> core object``; ``params`` are validated values by name,
        ``context`` a dict of what the graph knows (spacecraft, periods, onboard models,
        seed); see :mod:`adcs_nodes.entries`.
    inputs : tuple of str
        What it reads (:data:`INPUTS`).
    actuators : tuple of str
        What a controller commands (:data:`ACTUATORS`).
    node : tuple or None
        Sensors: ``(package, module, class, topic, message type)`` of the node publishing it.
    requires : tuple of str
        Scenario sections it needs besides its inputs, e.g. ``'spacecraft.wheels'``.
    targets : tuple of str
        Faults: what it may strike (``'sensor'``, ``'wheel'``, ``'magnetorquer'``).
    """

    kind: str
    name: str
    description: str
    core: str
    params: Tuple[Param, ...]
    build: Callable[[Dict[str, Any], Dict[str, Any]], Any]
    inputs: Tuple[str, ...] = ()
    actuators: Tuple[str, ...] = ()
    node: Optional[Tuple[str, str, str, str, str]] = None
    requires: Tuple[str, ...] = ()
    targets: Tuple[str, ...] = ()
    origin: str = field(default='', compare=False)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f'entry {self.name}: kind must be one of {KINDS}')
        bad = [i for i in self.inputs if i not in INPUTS]
        bad += [a for a in self.actuators if a not in ACTUATORS]
        if bad:
            raise ValueError(f'entry {self.name}: unknown inputs/actuators {bad}')
        names = [p.name for p in self.params]
        if len(set(names)) != len(names):
            raise ValueError(f'entry {self.name}: duplicate parameter names {names}')

    def param(self, name: str) -> Param:
        """The spec of parameter ``name`` (``KeyError`` with the known names)."""
        for p in self.params:
            if p.name == name:
                return p
        raise KeyError(f'{self.kind} {self.name} has no parameter {name!r}; known: '
                       f'{", ".join(p.name for p in self.params)}')

    def defaults(self) -> Dict[str, Any]:
        """``{name: default}`` of every parameter."""
        return {p.name: p.default for p in self.params}

    def validate(self, given: Dict[str, Any]) -> Dict[str, Any]:
        """Defaults overlaid with ``given``, each validated; unknown names refused."""
        known = [p.name for p in self.params]
        for key in given:
            if key not in known:
                raise ValueError(unknown_message(key, known, f'{self.kind} {self.name}'))
        out = self.defaults()
        for key, value in given.items():
            out[key] = self.param(key).validate(value)
        return out


def unknown_message(key: str, known: Sequence[str], where: str) -> str:
    """'unknown parameter X of WHERE (did you mean Y?); known: ...'."""
    near = difflib.get_close_matches(str(key), list(known), n=1)
    hint = f' (did you mean {near[0]!r}?)' if near else ''
    return (f'unknown parameter {short(key, 60)} of {where}{hint}; known: '
            f'{", ".join(sorted(known))}')


# ---------------------------------------------------------------------- the registry
_ENTRIES: Dict[str, Dict[str, Entry]] = {k: {} for k in KINDS}
_LOADED: List[str] = []
#: Modules with the built-in entries; a missing optional one (the simulator) is skipped.
BUILTIN = ('adcs_nodes.entries', 'sim_node.entries')
ENTRY_POINT_GROUP = 'adcs.registry'


def register(entry: Entry) -> Entry:
    """Add ``entry``; the same name twice in one kind is an error (unless identical)."""
    have = _ENTRIES[entry.kind].get(entry.name)
    if have is not None and have != entry:
        raise ValueError(f'{entry.kind} {entry.name!r} is registered twice '
                         f'({have.origin or have.core} and {entry.origin or entry.core})')
    _ENTRIES[entry.kind][entry.name] = entry
    return entry


def _load_builtin() -> None:
    if _LOADED:
        return
    _LOADED.append('builtin')
    for module in BUILTIN:
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name != module and not module.startswith(str(exc.name)):
                raise
    try:
        from importlib.metadata import entry_points
        for ep in entry_points(group=ENTRY_POINT_GROUP):
            ep.load()
    except Exception as exc:  # a broken third-party plugin must not hide the built-ins
        print(f'adcs registry: entry point plugin failed to load: {exc}', file=sys.stderr)


def load_plugins(specs: Iterable[str], base_dir: str = '') -> None:
    """Import plugin modules (dotted names or ``.py`` paths, relative to ``base_dir``).

    Raises ``ValueError`` naming the plugin when it cannot be imported.
    """
    _load_builtin()
    for spec in specs:
        spec = str(spec)
        if spec in _LOADED:
            continue
        try:
            if spec.endswith('.py'):
                path = spec if os.path.isabs(spec) else os.path.join(base_dir, spec)
                name = 'adcs_plugin_' + os.path.splitext(os.path.basename(path))[0]
                mod_spec = importlib.util.spec_from_file_location(name, path)
                if mod_spec is None or not os.path.isfile(path):
                    raise ValueError(f'no such file {path}')
                module = importlib.util.module_from_spec(mod_spec)
                sys.modules[name] = module
                mod_spec.loader.exec_module(module)
            else:
                importlib.import_module(spec)
        except ValueError:
            raise
        except Exception as exc:
            raise ValueError(f'plugin {short(spec, 120)} failed to load: {exc}') from None
        _LOADED.append(spec)


def entries(kind: str) -> Dict[str, Entry]:
    """Every registered entry of ``kind`` by name (built-ins loaded on first use)."""
    _load_builtin()
    return dict(_ENTRIES[kind])


def names(kind: str) -> List[str]:
    """Registered names of ``kind``, in registration order."""
    return list(entries(kind))


def get(kind: str, name: str) -> Entry:
    """The entry ``kind``/``name``; ``ValueError`` with a did-you-mean if unknown."""
    known = entries(kind)
    if name not in known:
        near = difflib.get_close_matches(str(name), list(known), n=1)
        hint = f' (did you mean {near[0]!r}?)' if near else ''
        raise ValueError(f'unknown {kind} {short(name, 60)}{hint}; known: '
                         f'{", ".join(known)}')
    return known[name]
