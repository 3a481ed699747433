"""Node parameters from the registry's typed specs: descriptors, refusal, run-time checks.

* :func:`declare` declares one :class:`~adcs_nodes.registry.Param` with a
  ``ParameterDescriptor`` (description with unit and range, floating-point/integer range,
  read-only where a change needs a restart), taking a value given at start-up (params file,
  ``-p``) after validating it. A bad value is a ``ValueError`` naming the parameter.
* :func:`refuse_unknown` refuses, at start-up, any given parameter the node never asked for,
  with a did-you-mean and the known names.
* :func:`install_validator` adds a set-parameters callback: a run-time change of a spec'd
  parameter is validated (type, range, choices) and a read-only one refused, with the reason.

Parameters that every lockstep node has (``epoch``, ``seed``, ...) are spec'd in
:data:`COMMON`, so ``ros2 param describe`` documents every parameter of every node.
"""
from __future__ import annotations

import difflib
from typing import Any, Dict, Iterable, List

from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType, SetParametersResult)
from rclpy.exceptions import ParameterException
from rclpy.parameter import Parameter

from adcs_nodes.registry import Param, short

_ROS_TYPES = {'float': ParameterType.PARAMETER_DOUBLE, 'int': ParameterType.PARAMETER_INTEGER,
              'bool': ParameterType.PARAMETER_BOOL, 'str': ParameterType.PARAMETER_STRING,
              'float[]': ParameterType.PARAMETER_DOUBLE_ARRAY,
              'str[]': ParameterType.PARAMETER_STRING_ARRAY}

#: Parameters ROS itself gives every node; never "unknown".
ROS_BUILTIN = ('use_sim_time', 'start_type_description_service')
ROS_BUILTIN_PREFIXES = ('qos_overrides.',)


def descriptor(spec: Param) -> ParameterDescriptor:
    """The ``ParameterDescriptor`` of ``spec`` (ranges only for scalar numbers)."""
    d = ParameterDescriptor(name=spec.name, type=_ROS_TYPES[spec.type],
                            description=spec.doc(), read_only=spec.read_only)
    if spec.choices:
        d.additional_constraints = 'one of: ' + ', '.join(spec.choices)
    lo, hi = spec.min, spec.max
    if spec.type == 'float' and (lo is not None or hi is not None):
        d.floating_point_range = [FloatingPointRange(
            from_value=float(lo if lo is not None else -1e308),
            to_value=float(hi if hi is not None else 1e308), step=0.0)]
    elif spec.type == 'int' and (lo is not None or hi is not None):
        d.integer_range = [IntegerRange(
            from_value=int(lo if lo is not None else -2 ** 62),
            to_value=int(hi if hi is not None else 2 ** 62), step=0)]
    elif spec.type == 'float[]' and (lo is not None or hi is not None or spec.positive):
        d.additional_constraints = f'each element {spec.range_text()}'
    return d


def _specs(node) -> Dict[str, Param]:
    if not hasattr(node, '_adcs_specs'):
        node._adcs_specs = {}
        node._adcs_prefixes = set()
    return node._adcs_specs


def declare(node, spec: Param) -> Any:
    """Declare ``spec`` on ``node`` and return its validated value (given or default).

    Raises ``ValueError`` (a configuration error: exit code 2, no traceback) for a bad value
    or type, including the errors rclpy raises itself.
    """
    try:
        return _declare(node, spec)
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
        if given is None and spec.type.endswith('[]'):
            given = []       # an empty YAML list arrives untyped (NOT_SET)
        if given is not None:
            if spec.type == 'float' and isinstance(given, int) and not isinstance(given, bool):
                given = float(given)
            if spec.type == 'float[]' and isinstance(given, (list, tuple)):
                given = [float(v) if isinstance(v, int) and not isinstance(v, bool) else v
                         for v in given]
            value = spec.validate(list(given) if isinstance(given, tuple) else given)
    if spec.type.endswith('[]') and not value:
        # an empty array has no type in ROS: declare it typed, with an empty value
        ptype = Parameter.Type.DOUBLE_ARRAY if spec.type == 'float[]' else \
            Parameter.Type.STRING_ARRAY
        node.declare_parameter(spec.name, Parameter(spec.name, ptype, []).value,
                               descriptor(spec))
        return list(value)
    node.declare_parameter(spec.name, value, descriptor(spec))
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


def describe_given(node, name: str, doc: str) -> None:
    """Attach a description to a parameter declared from the overrides (section keys)."""
    if not node.has_parameter(name) or name in _specs(node):
        return
    param = node.get_parameter(name)
    node.undeclare_parameter(name)
    node.declare_parameter(name, param.value, ParameterDescriptor(
        name=name, type=param.type_.value, description=doc, read_only=True))


def declare_all(node, specs: Iterable[Param]) -> Dict[str, Any]:
    """:func:`declare` each spec; returns ``{name: value}``."""
    return {s.name: declare(node, s) for s in specs}


def known_prefix(node, prefix: str) -> None:
    """Mark every parameter under ``prefix.`` as known (variant sections: orbit, field)."""
    _specs(node)
    node._adcs_prefixes.add(prefix.rstrip('.') + '.')


def refuse_unknown(node, also_known: Iterable[str] = ()) -> None:
    """Raise ``ValueError`` if a parameter was given that the node does not know."""
    specs = _specs(node)
    known = set(specs) | set(also_known) | set(getattr(node, '_asked', ()))
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


def install_validator(node) -> None:
    """Validate run-time changes of spec'd parameters (set-parameters callback)."""
    specs = _specs(node)

    def on_set(parameters: List[Parameter]) -> SetParametersResult:
        for p in parameters:
            spec = specs.get(p.name)
            if spec is None:
                continue
            if spec.read_only:
                return SetParametersResult(successful=False,
                                           reason=f'{p.name} is read-only: restart to change')
            try:
                value = p.value
                spec.validate(list(value) if isinstance(value, tuple) else value)
            except ValueError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_set)


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
    Param('plugins', 'str[]', [], '-', 'registry plugin modules or .py files to load',
          read_only=True),
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
    Param('timing_mode', 'str', '', '-', "lockstep (with the simulator) or live (real "
          "drivers); '': live when started alone", choices=('', 'lockstep', 'live'),
          read_only=True),
)}
