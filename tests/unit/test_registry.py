"""The registry (adcs_nodes/registry.py) and what is generated from it.

Typed parameter checks, did-you-mean for unknown names, plugin loading errors, and the
scenario/graph behaviour that comes from entries: wheels-only spacecraft, controllers refused
with a reason when their actuators or sensors are missing, external sensors.
"""
import math
import os
import re

import pytest
import yaml

from adcs_nodes import registry
from adcs_nodes.registry import Param
from adcs_nodes.graph import build_graph
from adcs_nodes.tools.run.launcher import external_devices
from adcs_nodes.scenario import ScenarioError, load_scenario, schema

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCEN = os.path.join(ROOT, 'scenarios')


def test_param_checks_type_range_choices_and_length():
    p = Param('k', 'float', 1.0, 'N m s', 'gain', positive=True, max=10.0)
    assert p.validate(2) == 2.0 and isinstance(p.validate(2), float)
    for bad, why in ((0.0, '> 0'), (11.0, '<= 10'), (float('nan'), 'finite'),
                     ('x', 'number'), (True, 'number')):
        with pytest.raises(ValueError, match=why):
            p.validate(bad)
    c = Param('mode', 'str', 'a', '-', 'mode', choices=('alpha', 'a'))
    with pytest.raises(ValueError, match="did you mean 'alpha'"):
        c.validate('alpa')
    v = Param('v', 'float[]', [0.0] * 3, '-', 'vector', length=3, min=-1.0)
    with pytest.raises(ValueError, match='3 values'):
        v.validate([0.0, 0.0])
    with pytest.raises(ValueError, match='>= -1'):
        v.validate([0.0, -2.0, 0.0])
    with pytest.raises(ValueError):          # a default outside its own range is a bug
        Param('bad', 'float', -1.0, '-', 'x', positive=True)


def test_unknown_names_get_a_did_you_mean_and_huge_names_are_cut():
    with pytest.raises(ValueError, match="did you mean 'magnetic'"):
        registry.get('controller', 'magnetik')
    with pytest.raises(ValueError) as err:
        registry.get('controller', 'x' * 100_000)
    assert len(str(err.value)) < 1000


def test_a_broken_plugin_is_named_in_the_error(tmp_path):
    bad = tmp_path / 'broken.py'
    bad.write_text('raise RuntimeError("boom")\n')
    with pytest.raises(ValueError, match='broken.py.*boom'):
        registry.load_plugins([str(bad)])
    with pytest.raises(ValueError, match='no such file'):
        registry.load_plugins([str(tmp_path / 'missing.py')])


def test_schema_defaults_are_the_entries_defaults():
    sch = schema()
    for kind, section in (('controller', sch['controllers']), ('sensor', sch['sensors'])):
        for name, entry in registry.entries(kind).items():
            for p in entry.params:
                assert section[name][p.name].default == p.default, (kind, name, p.name)
    for name, entry in registry.entries('estimator').items():
        for p in entry.params:
            assert sch['estimator'].keys({'algorithm': name})[p.name].default == p.default


def _write(tmp_path, sc):
    path = tmp_path / 'sc.yaml'
    path.write_text(yaml.safe_dump(sc))
    return str(path)


def _paper001():
    with open(os.path.join(SCEN, 'paper001_mpi.yaml')) as fh:
        return yaml.safe_load(fh)


def test_wheels_only_spacecraft_is_valid_and_builds_a_graph(tmp_path):
    sc = load_scenario(_write(tmp_path, _paper001()))
    assert 'magnetorquer' not in sc['spacecraft']
    names = [n.name for n in build_graph(sc, 10.0)]
    assert {'wheel_tachometer', 'guidance', 'mpi_controller', 'controller_manager'} <= set(names)
    assert 'magnetometer' not in names


def test_mpi_without_wheels_is_refused_with_the_reason(tmp_path):
    sc = _paper001()
    del sc['spacecraft']['wheels']
    del sc['sensors']['wheel_tachometer']
    with pytest.raises(ScenarioError, match='controllers.mpi: .*wheel'):
        load_scenario(_write(tmp_path, sc))


def test_magnetic_control_without_magnetorquer_is_refused(tmp_path):
    with open(os.path.join(SCEN, 'paper000_control.yaml')) as fh:
        sc = yaml.safe_load(fh)
    del sc['spacecraft']['magnetorquer']
    with pytest.raises(ScenarioError, match='magnetorquer'):
        load_scenario(_write(tmp_path, sc))


def test_an_external_sensor_gets_no_simulated_node_and_is_announced(tmp_path):
    with open(os.path.join(SCEN, 'paper000_estimation.yaml')) as fh:
        sc = yaml.safe_load(fh)
    sc['sensors']['magnetometer']['external'] = True
    loaded = load_scenario(_write(tmp_path, sc))
    names = [n.name for n in build_graph(loaded, 10.0)]
    assert 'magnetometer' not in names and 'estimator' in names
    lines = external_devices(loaded)
    assert len(lines) == 1 and 'sensors/magnetometer' in lines[0]
    assert 'sensor_msgs/msg/MagneticField' in lines[0]


def test_the_managers_point_mode_is_reachable_from_a_scenario(tmp_path):
    with open(os.path.join(SCEN, 'paper000_control.yaml')) as fh:
        sc = yaml.safe_load(fh)
    sc['manager'] = {'safe': 'bdot', 'auto': {'detumble': 'bdot', 'acquire': 'magnetic',
                                              'point': 'magnetic', 'angle_enter_deg': 10.0,
                                              'angle_exit_deg': 20.0}}
    loaded = load_scenario(_write(tmp_path, sc))
    man = next(n for n in build_graph(loaded, 10.0) if n.name == 'controller_manager')
    assert man.params['auto.point'] == 'magnetic' and man.params['auto.angle_enter_deg'] == 10.0
    from adcs_nodes.core.manager import AutoSequence
    auto = AutoSequence.from_dict({k[5:]: v for k, v in man.params.items()
                                   if k.startswith('auto.')})
    assert auto.controller_of('point') == 'magnetic'
    sc['manager']['auto'] = {'angle_enter_deg': 10.0}          # thresholds without a point
    with pytest.raises(ScenarioError, match='point'):
        load_scenario(_write(tmp_path, sc))
    sc['manager']['auto'] = {'point': 'mpi', 'angle_enter_deg': 10.0}
    with pytest.raises(ScenarioError, match="'mpi' is not a configured controller"):
        load_scenario(_write(tmp_path, sc))


#: Naming conventions every spec'd value follows (the validator checked them by name at run
#: time; now each spec states its range, checked here): pattern -> (lowest, highest) allowed
#: by the spec's range.
CONVENTIONS = (
    (re.compile(r'(^|_)std(_|$)|noise_std'), 0.0, math.inf, 'standard deviation'),
    (re.compile(r'probability'), 0.0, 1.0, 'probability'),
    (re.compile(r'^max_|_max$|limit|saturation|lsb|p0_diag'), 0.0, math.inf, 'limit'),
)


def _all_specs():
    from adcs_nodes.scenario import schema
    from adcs_nodes.spec import Section

    def walk(specs, prefix):
        for spec in specs:
            if isinstance(spec, Section):
                yield from walk(spec.params + tuple(p for v in spec.variants.values()
                                                    for p in v), f'{prefix}{spec.name}.')
            else:
                yield f'{prefix}{spec.name}', spec
                yield from walk(spec.fields, f'{prefix}{spec.name}[i].')
    yield from walk(schema().params, '')
    for kind in registry.KINDS:
        for name, entry in registry.entries(kind).items():
            yield from walk(entry.params, f'{kind} {name}: ')


def test_every_spec_follows_the_naming_conventions():
    """A standard deviation, a limit are >= 0 and a probability is in [0, 1] by their
    spec, so the validator, the plain engine and the nodes refuse the same values."""
    bad = []
    for key, spec in _all_specs():
        if spec.type not in ('float', 'int', 'float[]', 'vec3'):
            continue
        for pattern, low, high, what in CONVENTIONS:
            if not pattern.search(spec.name):
                continue
            lo = 0.0 if spec.positive else spec.min
            hi = math.inf if spec.max is None else spec.max
            if lo is None or lo < low or hi > high:
                bad.append(f'{key} ({what}): [{lo}, {hi}]')
    assert bad == []
