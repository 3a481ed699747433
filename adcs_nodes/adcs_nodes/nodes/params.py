"""Node parameters from their specs (:mod:`adcs_nodes.core.spec`): descriptors, refusal,
run-time checks.

* :func:`declare`: a ``Param`` with its ``ParameterDescriptor`` (meaning, unit, range or
  choices, read-only), taking the value given at start-up (params file, ``-p``) validated as
  everywhere else (``Param.from_ros``); a bad value is a ``ValueError`` naming it. A ``[]`` of
  a parameter file (``ros2 param dump`` writes them) arrives untyped: an array's empty list.
* Writable at run time only when the node applies a change (``node.applies_at_run_time``:
  a registered controller's own parameters); every other one is read-only.
* :func:`declare_section`: the sections (``orbit.*``, ``spacecraft.*``, ``auto.*``) read and
  validated with their ``Section`` spec, each key described, read-only.
* :func:`refuse_unknown` and :class:`SpecParameters` refuse an unknown name with a
  did-you-mean (start-up, run time); :func:`install_validator` validates a run-time change
  and hands it to the node. Every node's common parameters: :data:`adcs_nodes.spec.COMMON`.
"""
from __future__ import annotations

import array
from dataclasses import replace
from typing import Any, Dict, Iterable, List, Optional, Tuple

from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType, SetParametersResult)
from rclpy.exceptions import ParameterException
from rclpy.parameter import Parameter

from adcs_nodes.spec import COMMON, ROS_TYPE, Param, Section, did_you_mean, short

_ROS_TYPES = {'float': ParameterType.PARAMETER_DOUBLE, 'int': ParameterType.PARAMETER_INTEGER,
              'bool': ParameterType.PARAMETER_BOOL, 'str': ParameterType.PARAMETER_STRING,
              'float[]': ParameterType.PARAMETER_DOUBLE_ARRAY,
              'str[]': ParameterType.PARAMETER_STRING_ARRAY}
_ARRAY_TYPES = {'float[]': Parameter.Type.DOUBLE_ARRAY, 'str[]': Parameter.Type.STRING_ARRAY}


def _ros(spec: Param) -> str:
    """The ROS parameter type name of ``spec`` (a ``vec3`` is a ``float[]``, ...)."""
    return ROS_TYPE[spec.type]


#: Parameters ROS itself gives every node; never "unknown".
ROS_BUILTIN = ('use_sim_time', 'start_type_description_service')
ROS_BUILTIN_PREFIXES = ('qos_overrides.',)
#: Why a read-only parameter is read-only (the refusal of a run-time set says it).
READ_ONLY_WHY = ('the node reads it once, at start-up (a managed node: at configure); '
                 'cleanup and configure a managed node to change it (in a lockstep run it '
                 "rejoins at the world's frame), or set it for the next run")


# ---------------------------------------------------------------------- descriptions
def descriptor(spec: Param) -> ParameterDescriptor:
    """The ``ParameterDescriptor`` of ``spec``: a number range only when both ends are
    given (no fake ``-1e+308``) and below 2^61; the range text always in
    ``additional_constraints``."""
    d = ParameterDescriptor(name=spec.name, type=_ROS_TYPES[_ros(spec)],
                            description=spec.doc(), read_only=spec.read_only,
                            additional_constraints=spec.range_text())
    lo, hi = spec.min, spec.max
    if lo is not None and hi is not None and not spec.positive and max(-lo, hi) < 2**61:
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


def _given(node, name: str) -> Tuple[bool, Any]:
    """``(given, value)`` of parameter ``name`` at start-up: declared from the overrides
    (then undeclared, to be declared with its spec), or an untyped ``[]`` of a parameter file
    (``None``: rclpy cannot declare it, :class:`SpecParameters` left it out)."""
    if node.has_parameter(name):
        value = node.get_parameter(name).value
        node.undeclare_parameter(name)
        return True, value
    over = (getattr(node, '_parameter_overrides', None) or {}).get(name)
    return over is not None, None


def _declare(node, spec: Param) -> Any:
    specs = _specs(node)
    if spec.name in specs:
        raise ValueError(f'parameter {spec.name} is declared twice (a registry entry may not '
                         "reuse a name of the node's own parameters)")
    specs[spec.name] = spec
    given, raw = _given(node, spec.name)
    value = spec.default if spec.default is None else spec.validate(spec.default)
    if given and (raw is not None or _ros(spec).endswith('[]')):    # (a YAML null: default)
        value = spec.from_ros(raw)
    if value is None:          # an optional parameter not given: typed, without a value
        node.declare_parameter(spec.name, Parameter.Type(_ROS_TYPES[_ros(spec)]),
                               descriptor(spec), ignore_override=True)
        return None
    stored = spec.flat_value(value)
    if _ros(spec).endswith('[]') and not stored:
        # rclpy types an empty list as a byte array and has no public way to give a
        # read-only parameter a typed empty value: declare it typed (value not set), then
        # store the typed empty array
        ptype = _ARRAY_TYPES[_ros(spec)]
        node.declare_parameter(spec.name, ptype, descriptor(spec), ignore_override=True)
        node._parameters[spec.name] = Parameter(spec.name, ptype, [])
        return value
    node.declare_parameter(spec.name, stored, descriptor(spec), ignore_override=True)
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
def declare_section(node, prefix: str, section: Section) -> Dict[str, Any]:
    """The section ``prefix.*`` of the given parameters, validated as a scenario's section is
    (:meth:`Section.read`: a key it does not have is refused with a did-you-mean, a value
    out of its range naming the key; a node started alone gets the section's standalone
    values), each given key declared read-only with its descriptor."""
    _specs(node)
    node._adcs_prefixes.add(prefix + '.')
    flat = dict(section.flat_params(prefix))
    given = {k: _plain(p.value) for k, p in (getattr(node, '_parameter_overrides', None)
                                             or {}).items() if k.startswith(prefix + '.')}
    values = section.read(given, prefix)
    for name, value in given.items():
        if value is not None and name not in _specs(node):
            declare(node, replace(flat[name], read_only=True))
    return values


# ---------------------------------------------------------------------- refusal
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
        hints = [short(b, 60) + did_you_mean(b, names) for b in bad]
        raise ValueError(f'unknown parameter(s) {", ".join(hints)}; known: {", ".join(names)}')


def screen(node, parameters: List[Parameter]) -> Tuple[Optional[SetParametersResult],
                                                       List[Parameter]]:
    """A run-time set request before rclpy sees it: ``(refusal or None, parameters)``: an
    unknown name (did-you-mean) or a read-only parameter is refused; values are typed where
    the ``ros2`` CLI cannot (``2`` for a float, ``[]`` for an array)."""
    specs = _specs(node)
    out = []
    for p in parameters:
        if not node.has_parameter(p.name):
            return SetParametersResult(successful=False, reason=(
                f'unknown parameter {short(p.name, 60)}{did_you_mean(p.name, node._parameters)}'
                ': the node has no such parameter (ros2 param list shows its parameters)')), \
                parameters
        if node.describe_parameter(p.name).read_only:
            return SetParametersResult(successful=False, reason=(
                f'{p.name} is read-only: {READ_ONLY_WHY}')), parameters
        spec = specs.get(p.name)
        rtype = Parameter.Type(_ROS_TYPES[_ros(spec)]) if spec is not None else None
        if spec is not None and p.type_ not in (Parameter.Type.NOT_SET, rtype):
            value = spec.coerce(p.value)
            if _ros(spec).endswith('[]') and value == []:
                p = Parameter(p.name, _ARRAY_TYPES[_ros(spec)], [])
            else:
                try:
                    converted = Parameter(p.name, value=value)
                except TypeError:        # not a ROS value: rclpy's type check refuses it
                    converted = p
                if converted.type_ == rtype:
                    p = converted
        out.append(p)
    return None, out


class SpecParameters:
    """Mixin for an rclpy ``Node`` whose parameters come from specs: every run-time set
    (the ``SetParameters`` services, :meth:`set_parameters`) goes through :func:`screen`
    first. Put it before ``Node`` in the bases."""

    def declare_parameters(self, namespace, parameters, ignore_override=False):
        """``Node.declare_parameters``, leaving out the untyped values rclpy cannot declare
        (a ``[]`` in a parameter file): :func:`declare` takes them as the empty list."""
        kept = [p for p in parameters
                if not (isinstance(p, tuple) and len(p) > 1 and p[1] is None)]
        return super().declare_parameters(namespace, kept, ignore_override)

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
                values[p.name] = spec.from_ros(p.value)
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
            cells = (f'`{name}_controller`', f'`{p.name}`', p.type, p.unit, p.range_text(),
                     p.description)
            rows.append('| ' + ' | '.join(str(c).replace('|', '\\|') for c in cells) + ' |')
    return '\n'.join([WRITABLE_BEGIN] + rows + [WRITABLE_END]) + '\n'


if __name__ == '__main__':      # the table of docs/topics.md
    print(writable_markdown(), end='')
