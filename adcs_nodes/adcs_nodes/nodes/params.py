"""Node parameters from the registry's typed specs: descriptors, refusal, run-time checks.

* :func:`declare` declares one :class:`~adcs_nodes.registry.Param` with a
  ``ParameterDescriptor`` (:func:`description`: meaning, unit and range, or the choices;
  a closed floating-point/integer range; read-only), taking a value given at start-up
  (params file, ``-p``) after validating it. A bad value is a ``ValueError`` naming the
  parameter. An empty list is declared with its own array type (rclpy would type it a byte
  array).
* A parameter is writable at run time only when the node applies a change
  (``node.applies_at_run_time(name)``; :class:`~adcs_nodes.nodes.lockstep_node.LockstepNode`:
  a registered controller's own parameters, rebuilt at the next frame boundary). Every other
  one is declared read-only, whatever its spec says: the node reads it once (start-up or
  ``configure``), so a change would be accepted and never take effect.
* :func:`refuse_unknown` refuses, at start-up, any given parameter the node never asked for,
  with a did-you-mean and the known names; :class:`SpecParameters` refuses the same at run
  time (the nodes do not allow undeclared parameters).
* :func:`install_validator` adds a set-parameters callback: a run-time change of a spec'd
  parameter is validated (type, range, choices, the node's own check) and, when it passes,
  handed to the node to apply at its next frame boundary.
* Sections (``orbit.*``, ``onboard_field.*``, ``auto.*``, ...: nested scenario sections the
  models read as a dict) are declared key by key from what the launcher passes, each with
  its spec (:data:`SECTION_PARAMS`, or the node class's own ``SECTION_PARAMS``); read-only.

Parameters that every lockstep node has (``epoch``, ``seed``, ...) are spec'd in
:data:`COMMON`, so ``ros2 param describe`` documents every parameter of every node.
"""
from __future__ import annotations

import array
import difflib
from dataclasses import replace
from typing import Any, Dict, Iterable, List, Optional, Tuple

from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType, SetParametersResult)
from rclpy.exceptions import ParameterException
from rclpy.parameter import Parameter

from adcs_nodes.registry import Param, short

_ROS_TYPES = {'float': ParameterType.PARAMETER_DOUBLE, 'int': ParameterType.PARAMETER_INTEGER,
              'bool': ParameterType.PARAMETER_BOOL, 'str': ParameterType.PARAMETER_STRING,
              'float[]': ParameterType.PARAMETER_DOUBLE_ARRAY,
              'str[]': ParameterType.PARAMETER_STRING_ARRAY}
_ARRAY_TYPES = {'float[]': Parameter.Type.DOUBLE_ARRAY, 'str[]': Parameter.Type.STRING_ARRAY}

#: Parameters ROS itself gives every node; never "unknown".
ROS_BUILTIN = ('use_sim_time', 'start_type_description_service')
ROS_BUILTIN_PREFIXES = ('qos_overrides.',)
#: Why a read-only parameter is read-only (the refusal of a run-time set says it).
READ_ONLY_WHY = ('the node reads it once, at start-up (a managed node: at configure); '
                 'cleanup and configure a managed node to change it (in a lockstep run it '
                 "rejoins at the world's frame), or set it for the next run")


# ---------------------------------------------------------------------- descriptions
def range_text(spec: Param) -> str:
    """Unit-free range (or choices) of ``spec``, never empty for a number or a choice."""
    t = spec.type
    if spec.choices:
        return 'one of: ' + ', '.join(repr(c) if c == '' else c for c in spec.choices)
    if t == 'bool':
        return 'true or false'
    if t == 'str':
        return 'text'
    if t == 'str[]':
        return 'list of text' + (f', {spec.length} values' if spec.length else '')
    rng = spec.range_text()
    if t == 'int':
        return rng or 'any integer'
    if t == 'float':
        return rng or 'any finite number'
    each = f'each {rng}' if rng else 'any finite numbers'
    return each + (f', {spec.length} values' if spec.length else '')


def description(spec: Param) -> str:
    """What ``ros2 param describe`` prints: meaning, ``[unit]`` of a number (``[-]``:
    dimensionless), ``(range)`` or ``(one of: ...)``, and ``(read-only: ...)``."""
    text = spec.description.strip() or spec.name
    if spec.type in ('float', 'int', 'float[]'):
        text += f' [{spec.unit or "-"}]'
    text += f' ({range_text(spec)})'
    if spec.read_only:
        text += ' (read-only: restart to change)'
    return text


def descriptor(spec: Param) -> ParameterDescriptor:
    """The ``ParameterDescriptor`` of ``spec``.

    A floating-point or integer range only when both ends are given (a half-open one would
    print a fake bound such as ``-1e+308``); the range, the choices or the length rule is
    always in ``additional_constraints`` too.
    """
    d = ParameterDescriptor(name=spec.name, type=_ROS_TYPES[spec.type],
                            description=description(spec), read_only=spec.read_only,
                            additional_constraints=range_text(spec))
    lo, hi = spec.min, spec.max
    if lo is not None and hi is not None and not spec.positive:
        if spec.type == 'float':
            d.floating_point_range = [FloatingPointRange(from_value=float(lo),
                                                         to_value=float(hi), step=0.0)]
        elif spec.type == 'int':
            d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
    return d


# ---------------------------------------------------------------------- declaration
def _specs(node) -> Dict[str, Param]:
    if not hasattr(node, '_adcs_specs'):
        node._adcs_specs = {}
        node._adcs_prefixes = set()
    return node._adcs_specs


def _plain(value: Any) -> Any:
    """A parameter value as the specs validate it (arrays as lists)."""
    if isinstance(value, (tuple, array.array)):
        return list(value)
    return value


def _as_spec_type(spec: Param, value: Any) -> Any:
    """``value`` converted where ROS typing differs from the spec's: an integer for a float,
    integers in a float array, an untyped or other-typed empty list for an array."""
    value = _plain(value)
    if spec.type.endswith('[]') and (value is None or value == [] or value == b''):
        return []      # an empty YAML list arrives untyped (NOT_SET); the CLI's "[]" is bool[]
    if spec.type == 'float' and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if spec.type == 'float[]' and isinstance(value, list):
        return [float(v) if isinstance(v, int) and not isinstance(v, bool) else v
                for v in value]
    return value


def writable(node, spec: Param) -> Param:
    """``spec`` as the node declares it: read-only unless the node applies a run-time change
    (see the module docstring)."""
    applies = getattr(node, 'applies_at_run_time', None)
    if spec.read_only or (applies is not None and applies(spec.name)):
        return spec
    return replace(spec, read_only=True)


def declare(node, spec: Param) -> Any:
    """Declare ``spec`` on ``node`` and return its validated value (given or default).

    Raises ``ValueError`` (a configuration error: exit code 2, no traceback) for a bad value
    or type, including the errors rclpy raises itself.
    """
    try:
        return _declare(node, writable(node, spec))
    except ParameterException as exc:   # (InvalidParameterType..., Immutable... are these)
        raise ValueError(f'parameter {spec.name}: {exc}') from None


def _declare(node, spec: Param) -> Any:
    specs = _specs(node)
    if spec.name in specs:
        raise ValueError(f'parameter {spec.name} is declared twice (a registry entry may not '
                         "reuse a name of the node's own parameters)")
    specs[spec.name] = spec
    value = spec.default
    if node.has_parameter(spec.name):          # declared from the overrides: take the value
        given = node.get_parameter(spec.name).value
        node.undeclare_parameter(spec.name)
        if given is not None or spec.type.endswith('[]'):   # (a YAML null: the default)
            value = spec.validate(_as_spec_type(spec, given))
    value = list(value) if spec.type.endswith('[]') else value
    if spec.type.endswith('[]') and not value:
        # rclpy types an empty list as a byte array and has no public way to give a
        # read-only parameter a typed empty value: declare it typed (value not set), then
        # store the typed empty array
        ptype = _ARRAY_TYPES[spec.type]
        node.declare_parameter(spec.name, ptype, descriptor(spec), ignore_override=True)
        node._parameters[spec.name] = Parameter(spec.name, ptype, [])
        return value
    node.declare_parameter(spec.name, value, descriptor(spec), ignore_override=True)
    return value


def infer(name: str, default: Any, doc: str) -> Param:
    """A :class:`Param` for a node-local parameter documented by ``doc`` (type from default)."""
    if isinstance(default, bool):
        ptype = 'bool'
    elif isinstance(default, int):
        ptype = 'int'
    elif isinstance(default, float):
        ptype = 'float'
    elif isinstance(default, str):
        ptype = 'str'
    elif isinstance(default, (list, tuple)) and default and all(
            isinstance(v, str) for v in default):
        ptype = 'str[]'
    else:
        ptype = 'float[]'
        default = [float(v) for v in default]
    return Param(name, ptype, default, '-', doc)


def declare_all(node, specs: Iterable[Param]) -> Dict[str, Any]:
    """:func:`declare` each spec; returns ``{name: value}``."""
    return {s.name: declare(node, s) for s in specs}


# ---------------------------------------------------------------------- sections
def _p(name, ptype, default, unit, doc, **kw) -> Param:
    return Param(name, ptype, default, unit, doc, read_only=True, **kw)


#: ``orbit.*`` (the world) and ``onboard_orbit.*`` (the flight software's own model): the
#: keys of :func:`adcs_nodes.core.orbit.make_orbit` (docs/scenarios.md: ``orbit``).
ORBIT_PARAMS = (
    _p('type', 'str', 'circular', '-', 'orbit model', choices=('circular', 'tle')),
    _p('altitude_km', 'float', 690.0, 'km', 'circular: altitude above the reference radius',
       positive=True, max=1e6),
    _p('inclination_deg', 'float', 98.0, 'deg', 'circular: inclination', min=0.0, max=180.0),
    _p('raan_deg', 'float', 0.0, 'deg', 'circular: right ascension of the ascending node',
       min=-360.0, max=360.0),
    _p('arg_latitude0_deg', 'float', 0.0, 'deg', 'circular: argument of latitude at the '
       'epoch', min=-360.0, max=360.0),
    _p('line1', 'str', '', '-', 'tle: two-line element set, line 1'),
    _p('line2', 'str', '', '-', 'tle: two-line element set, line 2'),
)
#: ``field.*`` and ``onboard_field.*``: the keys of
#: :func:`adcs_nodes.core.geomag.make_field` (docs/scenarios.md: ``field``).
FIELD_PARAMS = (
    _p('model', 'str', 'dipole', '-', 'geomagnetic model',
       choices=('dipole', 'igrf_dipole', 'igrf')),
    _p('b0_T', 'float', 3e-5, 'T', 'dipole: strength at the reference radius', positive=True,
       max=1e-3),
    _p('r_ref_m', 'float', 6371200.0, 'm', 'dipole: reference radius of b0_T', positive=True,
       max=1e9),
    _p('pole_colatitude_deg', 'float', 0.0, 'deg', 'dipole: geographic colatitude of the '
       'dipole axis', min=0.0, max=180.0),
    _p('pole_longitude_deg', 'float', 0.0, 'deg', 'dipole: geographic east longitude of the '
       'axis', min=-360.0, max=360.0),
    _p('coefficient_date', 'str', '', '-', 'igrf_dipole: date of the IGRF degree-1 '
       'coefficients (ISO 8601; default: the epoch)'),
    _p('max_degree', 'int', 13, '-', 'igrf: truncation degree of the expansion', min=1,
       max=13),
)
#: ``auto.*`` of the controller manager: the automatic mode sequence
#: (:meth:`adcs_nodes.core.manager.AutoSequence.from_dict`; docs/scenarios.md:
#: ``manager.auto``).
AUTO_PARAMS = (
    _p('detumble', 'str', 'bdot', '-', 'controller of the detumble mode'),
    _p('acquire', 'str', 'magnetic', '-', 'controller of the acquire mode'),
    _p('point', 'str', '', '-', 'controller of the optional point mode'),
    _p('rate_enter_deg_s', 'float', 0.5, 'deg/s', 'detumble -> acquire below this rate',
       min=0.0),
    _p('rate_exit_deg_s', 'float', 1.0, 'deg/s', 'acquire -> detumble above this rate',
       min=0.0),
    _p('confirm_frames', 'int', 10, '-', 'frames the forward condition must hold', min=1,
       max=1000000),
    _p('exit_confirm_frames', 'int', 1, '-', 'frames the back condition must hold', min=1,
       max=1000000),
    _p('angle_enter_deg', 'float', 10.0, 'deg', 'acquire -> point below this attitude error',
       min=0.0, max=180.0),
    _p('angle_exit_deg', 'float', 20.0, 'deg', 'point -> acquire above this attitude error',
       min=0.0, max=180.0),
    _p('rate_frame', 'str', 'eci', '-', 'rate compared: w.r.t. ECI or the orbit frame',
       choices=('eci', 'orbit')),
)
#: Section specs by prefix, for every node (a node class adds its own in ``SECTION_PARAMS``).
SECTION_PARAMS: Dict[str, Tuple[Param, ...]] = {
    'orbit': ORBIT_PARAMS, 'onboard_orbit': ORBIT_PARAMS,
    'field': FIELD_PARAMS, 'onboard_field': FIELD_PARAMS,
    'auto': AUTO_PARAMS,
}


def section_specs(node, prefix: str) -> Optional[Dict[str, Param]]:
    """``{key: Param}`` of section ``prefix`` on ``node``, or None when it has no specs."""
    specs = {**SECTION_PARAMS, **getattr(node, 'SECTION_PARAMS', {})}.get(prefix)
    return None if specs is None else {p.name: p for p in specs}


def declare_section(node, prefix: str) -> Dict[str, Any]:
    """The given ``prefix.*`` parameters as ``{key: value}``, each declared with its spec
    (validated, described, read-only); a key without a spec is refused with a did-you-mean.

    A section whose prefix has no specs (a plugin's) keeps the given parameters as they are,
    read-only, with a pointer to ``docs/scenarios.md``.
    """
    known_prefix(node, prefix)
    specs = section_specs(node, prefix)
    given = {k: p.value for k, p in node.get_parameters_by_prefix(prefix).items()}
    out = {}
    for key, value in given.items():
        name = f'{prefix}.{key}'
        if name in _specs(node):                 # declared already (a second read)
            out[key] = _plain(node.get_parameter(name).value)
            continue
        if specs is None:
            _describe_given(node, name, f'{prefix} section key {key} [see docs/scenarios.md] '
                            '(as given)')
            out[key] = _plain(value)
            continue
        if key not in specs:
            near = difflib.get_close_matches(key, list(specs), n=1)
            hint = f" (did you mean '{prefix}.{near[0]}'?)" if near else ''
            raise ValueError(f'unknown parameter {short(name, 60)}{hint}; known in '
                             f'{prefix}.*: {", ".join(sorted(specs))}')
        out[key] = declare(node, replace(specs[key], name=name, read_only=True))
    return out


def _describe_given(node, name: str, doc: str) -> None:
    param = node.get_parameter(name)
    node.undeclare_parameter(name)
    node.declare_parameter(name, param.value, ParameterDescriptor(
        name=name, type=param.type_.value, description=doc, read_only=True),
        ignore_override=True)


def known_prefix(node, prefix: str) -> None:
    """Mark every parameter under ``prefix.`` as known (variant sections: orbit, field)."""
    _specs(node)
    node._adcs_prefixes.add(prefix.rstrip('.') + '.')


# ---------------------------------------------------------------------- refusal
def _unknown_reason(name: str, known: Iterable[str]) -> str:
    names = sorted(known)
    near = difflib.get_close_matches(name, names, n=1)
    hint = f' (did you mean {near[0]!r}?)' if near else ''
    return (f'unknown parameter {short(name, 60)}{hint}: the node has no such parameter '
            '(ros2 param list shows its parameters)')


def refuse_unknown(node, also_known: Iterable[str] = ()) -> None:
    """Raise ``ValueError`` if a parameter was given that the node does not know.

    The :data:`COMMON` names are known (a node may read one after this check, e.g.
    ``expected_publishers`` when its inputs are created).
    """
    specs = _specs(node)
    known = set(specs) | set(also_known) | set(getattr(node, '_asked', ())) | set(COMMON)
    given = list(getattr(node, '_parameter_overrides', {}) or {})
    prefixes = tuple(node._adcs_prefixes) + ROS_BUILTIN_PREFIXES
    bad = [g for g in given if g not in known and g not in ROS_BUILTIN
           and not g.startswith(prefixes)]
    if bad:
        names = sorted(known)
        hints = []
        for b in bad:
            near = difflib.get_close_matches(b, names, n=1)
            hints.append(f'{short(b, 60)}' + (f' (did you mean {near[0]!r}?)' if near else ''))
        raise ValueError(f'unknown parameter(s) {", ".join(hints)}; known: {", ".join(names)}')


def screen(node, parameters: List[Parameter]) -> Tuple[Optional[SetParametersResult],
                                                       List[Parameter]]:
    """A run-time set request before rclpy sees it: ``(refusal or None, parameters)``.

    Refused: a name the node does not have (with a did-you-mean, as at start-up) and a
    read-only parameter (with the reason). The values of spec'd parameters are converted
    where the ``ros2`` CLI cannot type them (``2`` for a float, ``[]`` for an array).
    """
    specs = _specs(node)
    out = []
    for p in parameters:
        if not node.has_parameter(p.name):
            return SetParametersResult(successful=False, reason=_unknown_reason(
                p.name, node._parameters)), parameters
        if node.describe_parameter(p.name).read_only:
            return SetParametersResult(successful=False, reason=(
                f'{p.name} is read-only: {READ_ONLY_WHY}')), parameters
        spec = specs.get(p.name)
        if spec is not None and p.type_ not in (Parameter.Type.NOT_SET,
                                                Parameter.Type(_ROS_TYPES[spec.type])):
            value = _as_spec_type(spec, p.value)
            if spec.type.endswith('[]') and value == []:
                p = Parameter(p.name, _ARRAY_TYPES[spec.type], [])
            else:
                try:
                    converted = Parameter(p.name, value=value)
                except TypeError:        # not a ROS value: rclpy's type check refuses it
                    converted = p
                if converted.type_ == Parameter.Type(_ROS_TYPES[spec.type]):
                    p = converted
        out.append(p)
    return None, out


class SpecParameters:
    """Mixin for an rclpy ``Node`` whose parameters come from specs: every run-time set
    (the ``SetParameters`` services, :meth:`set_parameters`) goes through :func:`screen`
    first. Put it before ``Node`` in the bases."""

    def set_parameters(self, parameter_list: List[Parameter]) -> List[SetParametersResult]:
        """Each parameter set on its own (``Node.set_parameters``), screened: an unknown name
        is a refused result here, not an exception."""
        return [self.set_parameters_atomically([p]) for p in parameter_list]

    def set_parameters_atomically(self, parameter_list: List[Parameter]
                                  ) -> SetParametersResult:
        """All or none, screened (see :func:`screen`)."""
        refused, parameter_list = screen(self, list(parameter_list))
        if refused is not None:
            return refused
        return super().set_parameters_atomically(parameter_list)


def install_validator(node) -> None:
    """Validate run-time changes of spec'd parameters (set-parameters callback).

    A change passes the spec (type, range, choices, length) and the node's own check
    (``node.check_parameters({name: value}) -> reason or ''``); it is then handed to
    ``node.parameters_set(names)`` (the node applies it at its next frame boundary).
    """
    specs = _specs(node)

    def on_set(parameters: List[Parameter]) -> SetParametersResult:
        values = {}
        for p in parameters:
            spec = specs.get(p.name)
            if spec is None or not node.has_parameter(p.name):
                continue        # (a declaration: validated by declare, and not a change)
            if spec.read_only:
                return SetParametersResult(successful=False,
                                           reason=f'{p.name} is read-only: {READ_ONLY_WHY}')
            try:
                values[p.name] = spec.validate(_as_spec_type(spec, p.value))
            except ValueError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        check = getattr(node, 'check_parameters', None)
        reason = check(values) if values and check is not None else ''
        if reason:
            return SetParametersResult(successful=False, reason=reason)
        changed = getattr(node, 'parameters_set', None)
        if values and changed is not None:
            changed(list(values))
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_set)


# ---------------------------------------------------------------------- documentation
#: Markers of the generated table in docs/topics.md.
WRITABLE_BEGIN = ('<!-- writable parameters: generated by `python -m adcs_nodes.nodes.params` '
                  '(adcs_nodes.nodes.params.writable_markdown); do not edit -->')
WRITABLE_END = '<!-- end of the writable parameters -->'


def writable_markdown() -> str:
    """The parameters writable at run time, as a Markdown table (docs/topics.md): the own
    parameters of every built-in registered controller (``LockstepNode.applies_at_run_time``;
    a plugin controller's are writable too)."""
    from adcs_nodes import registry
    rows = ['| node | parameter | type | unit | range or choices | meaning |',
            '|---|---|---|---|---|---|']
    for name, entry in registry.entries('controller').items():
        if getattr(entry.build, '__module__', '') != 'adcs_nodes.entries':
            continue                                   # (a plugin loaded in this process)
        for p in entry.params:
            if p.read_only:
                continue
            cells = (f'`{name}_controller`', f'`{p.name}`', p.type, p.unit, range_text(p),
                     p.description)
            rows.append('| ' + ' | '.join(str(c).replace('|', '\\|') for c in cells) + ' |')
    return '\n'.join([WRITABLE_BEGIN] + rows + [WRITABLE_END]) + '\n'


#: Parameters every lockstep node has (spec'd here so each one is documented).
COMMON = {p.name: p for p in (
    Param('epoch', 'str', '2026-01-01T00:00:00Z', '-', 'UTC date-time of sim time 0 (ISO '
          '8601)', read_only=True),
    Param('frame_period_s', 'float', 1.0, 's', 'base frame period', positive=True,
          max=86400.0, read_only=True),
    Param('timeout_s', 'float', 5.0, 's', 'wall-clock wait for a missing input',
          positive=True, max=3600.0),
    Param('seed', 'int', 0, '-', 'scenario seed (each node derives its own stream)', min=0,
          read_only=True),
    Param('real_time', 'bool', False, '-', 'latest-value mode paced by the wall clock',
          read_only=True),
    Param('duration_s', 'float', 0.0, 's', 'run length; 0: unbounded', min=0.0,
          read_only=True),
    Param('expected_matches', 'str[]', [], '-', 'start handshake: pub:/sub:<topic>=<n> '
          'matched endpoints before ready', read_only=True),
    Param('expected_publishers', 'str[]', [''], '-', 'lockstep inputs accepted only from '
          "the named node's publisher: \"<topic>=<node>\" entries (['']: accept every "
          'publisher)', read_only=True),
    Param('plugins', 'str[]', [], '-', 'registry plugin modules or .py files to load',
          read_only=True),
    Param('autostart', 'bool', True, '-', 'managed nodes: configure and activate at start '
          '(false: wait for the lifecycle services)', read_only=True),
    Param('dead_after_frames', 'int', 3, '-', 'a producer that missed this many frames in a '
          'row is dead and no longer awaited until it publishes again', min=1, max=1000000),
    Param('max_sample_age_s', 'float', 5.0, 's', 'live mode: older samples are rejected',
          positive=True),
    Param('max_future_s', 'float', 0.5, 's', 'live mode: samples stamped further ahead of '
          'the clock are rejected', min=0.0),
    Param('live_latency_s', 'float', 0.05, 's', 'live mode: a frame with no new sample is '
          'stamped the clock time minus this (samples in transit are not late)', min=0.0,
          max=60.0),
    Param('status_period_s', 'float', 1.0, 's', 'lockstep/status period (sim time)',
          positive=True),
    Param('external_inputs', 'str[]', [], '-', 'lockstep mode: inputs taken in sample '
          'timing (a driver publishes them, or --real-time): never awaited, each sample used '
          'once at its own stamp, in stamp order; late ones rejected', read_only=True),
    Param('timing_mode', 'str', '', '-', "lockstep (with the simulator) or live (real "
          "drivers); '': live when started alone", choices=('', 'lockstep', 'live'),
          read_only=True),
    Param('killed_at_s', 'float', -1.0, 's', 'a node_killed fault: from this sim time on the '
          'node fires no frame and publishes nothing, as a crashed process (-1: never)',
          min=-1.0, read_only=True),
)}


if __name__ == '__main__':      # the table of docs/topics.md
    print(writable_markdown(), end='')
