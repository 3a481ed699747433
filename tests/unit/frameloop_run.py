"""Helpers of the FrameLoop behaviour tests (``tests/unit/test_frameloop_*.py``): a scenario
edited as its YAML text would be and validated like ``adcs run`` validates it, run on the
plain engine (:class:`sim_node.engine.FrameLoop`: no ROS, no process), its output gathered
per topic. Topics are named without the leading ``/``."""
import collections
import os

import numpy as np
import yaml

from adcs_nodes.inputs import converter
from adcs_nodes.msgs.fields import stamp_ns
from adcs_nodes.scenario import load_scenario
from sim_node.engine import FrameLoop

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENARIOS = os.path.join(ROOT, 'scenarios')
EPOCH_NS = 1767225600 * 10**9          # 2026-01-01T00:00:00Z, the shipped scenarios' epoch


def raw(name):
    """The shipped scenario ``name`` (without ``.yaml``) as its YAML text gives it."""
    with open(os.path.join(SCENARIOS, f'{name}.yaml')) as fh:
        return yaml.safe_load(fh)


def validated(tmp_path, sc, name='scenario'):
    """``sc`` written to ``tmp_path/<name>.yaml`` and loaded with the validator (what ``adcs
    run`` does with a scenario file)."""
    path = tmp_path / f'{name}.yaml'
    path.write_text(yaml.safe_dump(sc))
    return load_scenario(str(path))


def control_scenario(tmp_path, **changes):
    """paper000_control with a 2 s magnetometer (B-dot needs samples) and a 1 s input timeout,
    plus top-level ``changes``, validated (as ``tests/graph/adcs_launch.control_scenario``)."""
    sc = raw('paper000_control')
    sc['sensors']['magnetometer']['period_s'] = 2.0
    sc['timing']['timeout_s'] = 1.0
    sc.update(changes)
    return sc


def messages(frame, loop):
    """``[(topic, message)]`` of a frame: its core samples made messages by their topics'
    converters (what the bag sink writes and the nodes publish)."""
    return [(topic, converter(topic).to_msg(x, loop.epoch_ns)) for topic, x in frame.outputs]


def run(sc, duration_s=None):
    """Run the validated scenario ``sc`` to its end: ``({topic: [message, ...]}, loop)``
    (:func:`messages`)."""
    loop = FrameLoop.from_scenario(sc, duration_s)
    out = collections.defaultdict(list)
    for frame in loop.run():
        for topic, msg in messages(frame, loop):
            out[topic].append(msg)
    return out, loop


def t_s(msg):
    """Sim time [s] of a message's header stamp."""
    return (stamp_ns(msg.header.stamp) - EPOCH_NS) / 1e9


def by_t(msgs):
    """``{sim time [s] rounded to 1 us: message}``."""
    return {round(t_s(m), 6): m for m in msgs}


def q(msg):
    """A ``geometry_msgs/Quaternion`` as ``[x, y, z, w]``."""
    return np.array([msg.x, msg.y, msg.z, msg.w])


def v(msg):
    """A ``geometry_msgs/Vector3`` as ``[x, y, z]``."""
    return np.array([msg.x, msg.y, msg.z])


def source_runs(sources):
    """``['a', 'a', 'b', 'a']`` -> ``['a', 'b', 'a']``."""
    return [sources[0]] + [s for a, s in zip(sources, sources[1:]) if s != a]
