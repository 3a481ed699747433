"""Typed messages built by filling their slots: ``make(AttitudeState, header=..., ...)``.

Why (issue 13): the generated ``__init__`` of a message builds a default for every field
(sub-messages, arrays; each after a ``from ... import`` in its body), which the node glue then
replaces, and every field assignment goes through a Python property. For the messages the
nodes publish every frame that was about a fifth of a composed frame's CPU. With rosidl's
field checks off (the default, ``ROS_PYTHON_CHECK_FIELDS`` not 1) :func:`make` creates the
same object directly: it stores each given field in its slot with the conversion the generated
setter applies when checks are off, and nothing else:

* fixed-size numeric arrays (``float64[36]``): ``numpy.array(value, dtype=<the field's>)``;
* numeric sequences (``float64[]``): ``array.array(<the field's typecode>, value)``;
* anything else (sub-messages, strings, numbers, lists of messages or strings): as given.

The dtype or typecode of a field is read from a default instance of the class, once per class.
With checks on, :func:`make` calls the generated constructor (which checks every value).
Either way every field must be given (a missing or unknown name is a ``TypeError``), so the
fast path never leaves a slot unset. Tested byte for byte against ``serialize_message`` of the
generated constructor's message, for random values including NaN and inf
(``tests/unit/test_messages_fast.py``).

Sub-messages are not copied: as with the generated constructor, a message given as a field is
shared with the new message.
"""
from __future__ import annotations

import array
import sys
from typing import Any, Callable, Dict

import numpy as np

_BUILDERS: Dict[type, Callable[..., Any]] = {}


def checks_off(cls: type) -> bool:
    """True when rosidl's field checks are off for message class ``cls`` (its module's
    ``ros_python_check_fields``, read from ``ROS_PYTHON_CHECK_FIELDS`` at import)."""
    return getattr(sys.modules[cls.__module__], 'ros_python_check_fields', '1') != '1'


def make(cls: type, **fields: Any) -> Any:
    """A message of type ``cls`` with ``fields`` (every field of the type, by name).

    Parameters
    ----------
    cls : type
        Generated message class (``adcs_msgs.msg.Environment``, ``std_msgs.msg.Header``, ...).
    **fields
        One value per field of ``cls`` (``cls.get_fields_and_field_types()``), as the
        generated constructor takes them.

    Returns
    -------
    message
        Equal to ``cls(**fields)`` and serialized to the same bytes.
    """
    build = _BUILDERS.get(cls)
    if build is None:
        build = _BUILDERS[cls] = _builder(cls)
    return build(**fields)


def _builder(cls: type) -> Callable[..., Any]:
    """A function of the fields of ``cls`` (all keyword-only, all required) returning the
    message: slot filling when checks are off, the generated constructor when on."""
    names = list(cls.get_fields_and_field_types())
    args = ', '.join(names)
    if not checks_off(cls):
        body = [f'    return cls({", ".join(f"{n}={n}" for n in names)})']
    else:
        default = cls()
        body = ['    m = new(cls)', '    m._check_fields = False']
        for n in names:
            value = getattr(default, '_' + n)
            if isinstance(value, np.ndarray):
                body.append(f'    m._{n} = np_array({n}, dtype=np.{value.dtype.name})')
            elif isinstance(value, array.array):
                body.append(f'    m._{n} = py_array({value.typecode!r}, {n})')
            else:
                body.append(f'    m._{n} = {n}')
        body.append('    return m')
    source = f'def build(*, {args}):\n' + '\n'.join(body) + '\n'
    scope = {'cls': cls, 'new': object.__new__, 'np': np, 'np_array': np.array,
             'py_array': array.array}
    exec(compile(source, f'<adcs messages.make {cls.__name__}>', 'exec'), scope)  # noqa: S102
    return scope['build']
