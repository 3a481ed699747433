"""A recorded bag is data, never code (``docs/security.md``): its ``scenario.yaml`` goes
through the scenario file's guards; the plugins it names are never imported."""
from __future__ import annotations

import os
from typing import Any, Dict, List, Optional, Sequence

from adcs_nodes.scenario import ScenarioError, load_scenario, read_yaml, shorten_message

RULE = 'a bag is data: docs/security.md'


class BagError(ValueError):
    """The bag's scenario cannot be used; the message is one line."""


def _one_line(text: Any) -> str:
    return ' '.join(shorten_message(str(text)).split())


def scenario_path(bag: str) -> str:
    """``scenario.yaml`` beside the bag (a bag directory, or the directory of a ``.mcap``)."""
    folder = bag if os.path.isdir(bag) else os.path.dirname(os.path.abspath(bag))
    return os.path.join(folder, 'scenario.yaml')


def bag_scenario(bag: str) -> Optional[Dict[str, Any]]:
    """The bag's stored scenario as data (nothing validated or imported), None without one;
    BagError when the scenario file's guards refuse it or ``plugins`` is not a list."""
    path = scenario_path(bag)
    if not os.path.isfile(path):
        return None
    try:
        data = read_yaml(path)
    except ScenarioError as exc:
        raise BagError(_one_line(f'{exc} ({RULE})')) from None
    if not isinstance(data, dict):
        raise BagError(f'{path}: not a scenario (a YAML mapping) but {type(data).__name__} '
                       f'({RULE})')
    recorded_plugins(data, path)
    return data


def recorded_plugins(sc: Dict[str, Any], path: str) -> List[str]:
    """The plugins the recorded run used (its ``plugins:`` list)."""
    plugins = sc.get('plugins') or []
    if not isinstance(plugins, list) or not all(isinstance(p, str) for p in plugins):
        raise BagError(f'{path}: plugins: expected a list of module names or .py paths '
                       f'({RULE})')
    return [_one_line(p) for p in plugins]


def plugin_note(bag: str, sc: Optional[Dict[str, Any]]) -> str:
    """One line naming the plugins the run used, not imported ('' if none)."""
    used = recorded_plugins(sc, scenario_path(bag)) if sc else []
    return (f'{scenario_path(bag)}: the run used the plugins {", ".join(used)}; not imported '
            f'({RULE})') if used else ''


def validated_scenario(bag: str, plugins: Sequence[str] = ()) -> Dict[str, Any]:
    """The bag's scenario validated, importing the user's ``plugins``, never the bag's own;
    BagError without one, for a run that used plugins none are given for, or refused."""
    sc, path = bag_scenario(bag), scenario_path(bag)
    if sc is None:
        raise BagError(f'{bag}: no scenario.yaml beside the bag (adcs run --record writes it)')
    used = recorded_plugins(sc, path)
    if used and not plugins:
        raise BagError(f'{path}: the run used the plugins {", ".join(used)}; they are not '
                       f'imported from a bag ({RULE}): give them with --plugin if you trust '
                       'them')
    try:
        return load_scenario(path, plugins=[os.path.abspath(p) if p.endswith('.py') else p
                                            for p in plugins])
    except ScenarioError as exc:
        raise BagError(_one_line(exc)) from None
