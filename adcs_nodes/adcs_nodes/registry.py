"""The registry: every controller, estimator, sensor model and fault kind as an
:class:`Entry`, and the world's scenario sections. Plugins (a scenario's ``plugins`` or an
``adcs.registry`` entry point) call :func:`register`. No rclpy."""
from __future__ import annotations

import importlib
import importlib.util
import os
import sys
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, Iterable, List, Optional, Tuple

from adcs_nodes import inputs as _inputs
from adcs_nodes.spec import (TYPES, Param, Section, SpecError, did_you_mean,  # noqa: F401
                             short, unknown_message)

KINDS = ('controller', 'estimator', 'sensor', 'fault')

#: What a controller may read or an estimator may take (:mod:`adcs_nodes.inputs`).
INPUTS = _inputs.NAMES
#: What a controller may command.
ACTUATORS = ('magnetorquer', 'wheels', 'torque')


@dataclass(frozen=True)
class Entry:
    """One registered component of ``kind``, ``name`` unique in its kind: ``build(params,
    context) -> core object``; sensors' ``node`` = ``(package, module, class, topic, type)``;
    ``requires``: sections besides its inputs; ``check(values)``: a cross-parameter rule."""

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
    check: Optional[Callable[[Dict[str, Any]], Any]] = field(default=None, compare=False)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f'entry {self.name}: kind must be one of {KINDS}')
        bad = [i for i in self.inputs if i not in _inputs.BY_NAME]
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
        if self.check is not None:
            self.check(out)
        return out

    def section(self) -> Section:
        """Its parameters as an optional scenario section (``controllers.<name>``, ...)."""
        return Section(self.name, self.params, self.description, optional=True,
                       check=self.check)


# ---------------------------------------------------------------------- the registry
_ENTRIES: Dict[str, Dict[str, Entry]] = {k: {} for k in KINDS}
#: Scenario sections of the simulated world, registered by ``sim_node.entries``.
_SECTIONS: Dict[str, Section] = {}
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


def register_section(section: Section) -> Section:
    """Add a world section to the scenario schema (the same name twice: the last one)."""
    _SECTIONS[section.name] = section
    return section


def section(name: str) -> Section:
    """The registered world section ``name`` (``ValueError``: sim_node not installed)."""
    _load_builtin()
    if name not in _SECTIONS:
        raise ValueError(f'no section {name!r} is registered (is sim_node installed?)')
    return _SECTIONS[name]


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
    """Import plugin modules (dotted names or ``.py`` paths from ``base_dir``); ValueError."""
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
        raise ValueError(f'unknown {kind} {short(name, 60)}{did_you_mean(name, known)}; known: '
                         f'{", ".join(known)}')
    return known[name]
