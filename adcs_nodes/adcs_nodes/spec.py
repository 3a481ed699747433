"""The specs every node, the graph and the plain engine share: the run's timing, the common
node parameters (:data:`COMMON`), the guidance profile and the manager's schedule (the spec
language: :mod:`adcs_nodes.core.spec`). No rclpy."""
from __future__ import annotations

from dataclasses import replace

from adcs_nodes.core.spec import (REQUIRED, ROS_TYPE, TYPES, Param, Section,  # noqa: F401
                                  SpecError, did_you_mean, iso_time, plain, short,
                                  unknown_message)

#: The scenario's ``timing`` section.
FRAME_S = Param('frame_s', 'float', 1.0, 's', 'base frame period; every period is a multiple '
                'of it', min=1e-6, max=86400.0)
TIMEOUT_S = Param('timeout_s', 'float', 5.0, 's', 'wall-clock wait for a missing input before '
                  'going on', positive=True, max=3600.0)
SUBSTEPS = Param('substeps', 'int', 10, '-', 'RK4 substeps per frame in the dynamics', min=1,
                 max=10000)
TIMING = Section('timing', (FRAME_S, SUBSTEPS, TIMEOUT_S))
EPOCH = Param('epoch', 'time', '2026-01-01T00:00:00Z', '-', 'UTC date-time of sim time 0 '
              '(ISO 8601)')
SEED = Param('seed', 'int', 0, '-', 'scenario seed; every node derives its own random stream '
             'from it', min=0, max=2**63 - 1)

#: Wall-clock wait for a missing input [``timing.timeout_s``] by depth in the frame's chain:
#: a node waits longer than its producers, so a missing input times out upstream first; a
#: sensor waits for the next frame's truth, after the clock master's own wait.
CHAIN_TIMEOUT = {'estimator': 1.0, 'controller': 2.0, 'manager': 3.0, 'dynamics': 4.0,
                 'sensor': 5.0}

#: Parameters every lockstep node has.
COMMON = {p.name: p for p in (
    replace(EPOCH, read_only=True),
    replace(FRAME_S, name='frame_period_s', read_only=True),
    TIMEOUT_S,
    Param('timeout_factor', 'float', 1.0, '-', 'the wait for a missing input is timeout_s '
          "times this: the node's depth in the frame's chain (CHAIN_TIMEOUT; the launcher "
          'sets it)', min=1.0, max=max(CHAIN_TIMEOUT.values()), read_only=True),
    replace(SEED, read_only=True),
    Param('real_time', 'bool', False, '-', 'latest-value mode paced by the wall clock',
          read_only=True),
    Param('duration_s', 'float', None, 's', 'run length (not given: unbounded)',
          positive=True, read_only=True),
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


# ---------------------------------------------------------------------- guidance, schedule
def _segments(segments):
    """A profile's rules beyond each field's range; sorted by ``t_s``."""
    for i, seg in enumerate(segments):
        if seg['type'] == 'slew' and not seg['duration_s'] > 0:
            raise SpecError(f'[{i}].duration_s', 'a slew needs duration_s > 0')
        if seg['type'] == 'track' and not seg['period_s'] > 0:
            raise SpecError(f'[{i}].period_s', 'a track needs period_s > 0')
    return sorted(segments, key=lambda e: e['t_s'])


#: ``guidance.profile``: time-tagged attitude segments (:func:`adcs_nodes.core.guidance.
#: guidance_from_params`); the guidance node takes it as ``profile_<field>`` arrays.
PROFILE = Param(
    'profile', 'table', [], '-', 'time-tagged segments (empty: hold the orbital frame)',
    fields=(Param('t_s', 'float', REQUIRED, 's', 'start time of the segment', min=0.0),
            Param('type', 'str', REQUIRED, '-', 'segment type',
                  choices=('hold', 'slew', 'track')),
            Param('q_xyzw', 'quat', [0.0, 0.0, 0.0, 1.0], '-', 'attitude of the segment, '
                  'scalar last'),
            Param('duration_s', 'float', 0.0, 's', 'slew duration', min=0.0),
            Param('axis_body', 'vec3', [0.0, 0.0, 1.0], '-', 'tracking axis, body axes'),
            Param('amplitude_deg', 'float', 0.0, 'deg', 'tracking amplitude', min=0.0,
                  max=180.0),
            Param('period_s', 'float', 0.0, 's', 'tracking period', min=0.0)),
    check=_segments)
#: The segment of an empty profile: hold the orbital frame.
HOLD = PROFILE.validate([{'t_s': 0.0, 'type': 'hold'}])

#: ``manager.schedule``: scripted switches (the manager takes ``schedule_<field>`` arrays).
SCHEDULE = Param(
    'schedule', 'table', [], '-', 'scripted switches, in time order',
    fields=(Param('t_s', 'float', REQUIRED, 's', 'switch time'),
            Param('controller', 'str', REQUIRED, '-', 'controller switched to')),
    check=lambda items: sorted(items, key=lambda e: e['t_s']))
