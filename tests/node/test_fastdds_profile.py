"""The Fast DDS profile every process of a run gets (``adcs_nodes/config/fastdds_profiles.xml``).

The launcher's child environment names the profile unless the user named a profiles file of
their own. A node process started with that environment loads it without a parse error (a
broken copy shows that the parse check can fail) and its receive sockets get the profile's
4 MiB buffer (the kernel reports twice the size granted, capped by ``net.core.rmem_max``);
without the profile they keep the system default. The heartbeat period it sets has no
observable in rclpy; its effect was measured under load (docs/reliability.md).
"""
import json
import os
import subprocess
import sys

import pytest

pytest.importorskip('rclpy')

from domains import worker_domain  # noqa: E402
from adcs_nodes.tools.run.launcher import FASTDDS_PROFILES, child_env, profile_env  # noqa: E402

PROFILE_BUFFER_B = 4 * 1024 * 1024

#: Creates one rclpy node, then prints the SO_RCVBUF of every UDP socket of this process.
PROBE = r'''
import json, os, socket
import rclpy
rclpy.init()
node = rclpy.create_node('profile_probe')
sizes = []
for fd in os.listdir('/proc/self/fd'):
    try:
        s = socket.socket(fileno=os.dup(int(fd)))
    except OSError:
        continue
    try:
        if s.type == socket.SOCK_DGRAM:
            sizes.append(s.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF))
    finally:
        s.close()
node.destroy_node()
rclpy.shutdown()
print(json.dumps(sizes))
'''


def _probe(env):
    proc = subprocess.run([sys.executable, '-c', PROBE], env=env, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1]), proc.stderr


def _sysctl(name):
    with open(f'/proc/sys/net/core/{name}') as fh:
        return int(fh.read())


def test_child_env_names_the_profile_unless_the_user_named_one():
    assert os.path.isfile(FASTDDS_PROFILES)
    env = child_env(7)
    assert env['FASTDDS_DEFAULT_PROFILES_FILE'] == FASTDDS_PROFILES
    for key in ('FASTDDS_DEFAULT_PROFILES_FILE', 'FASTRTPS_DEFAULT_PROFILES_FILE'):
        assert profile_env({key: '/my/profiles.xml'}) == {}
        assert profile_env({key: ''}) == {}            # empty: the user wants no file
    assert profile_env({}) == {'FASTDDS_DEFAULT_PROFILES_FILE': FASTDDS_PROFILES}


def test_an_empty_profiles_file_means_none(monkeypatch):
    monkeypatch.setenv('FASTDDS_DEFAULT_PROFILES_FILE', '')
    assert 'FASTDDS_DEFAULT_PROFILES_FILE' not in child_env(7)   # not even the empty path


def test_a_node_loads_the_profile_and_gets_its_socket_buffers(tmp_path):
    env = child_env(worker_domain(120, 10))
    sizes, err = _probe(env)
    assert 'XMLPARSER' not in err, err
    # SO_RCVBUF reads back twice what was granted; the grant is capped by rmem_max
    assert max(sizes) == 2 * min(PROFILE_BUFFER_B, _sysctl('rmem_max')), sizes

    # control 1: without the profile the sockets keep the system default
    plain = {k: v for k, v in env.items() if k != 'FASTDDS_DEFAULT_PROFILES_FILE'}
    plain_sizes, plain_err = _probe(plain)
    assert max(plain_sizes) == _sysctl('rmem_default'), plain_sizes
    assert 'XMLPARSER' not in plain_err, plain_err

    # control 2: a profile Fast DDS cannot parse is reported on stderr
    with open(FASTDDS_PROFILES) as fh:
        broken = fh.read().replace('<heartbeat_period>', '<heartbeat_periodX>', 1)
    bad = tmp_path / 'broken.xml'
    bad.write_text(broken)
    _, bad_err = _probe(dict(env, FASTDDS_DEFAULT_PROFILES_FILE=str(bad)))
    assert 'XMLPARSER' in bad_err
