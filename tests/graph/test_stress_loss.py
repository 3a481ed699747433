"""Reliable delivery under heavy load (``make stress``; slow, not in ``make test``).

Three recorded runs of paper000_control at once (2 s magnetometer, 1 s input timeout, 8000 s
of sim time each) beside three CPU burners on the machine: no node may miss a frame, the
middleware may report no lost message, and each bag must hold every estimate and every
command (one each 2 s). With Fast DDS's default 3 s heartbeat this failed in 6 of 9 runs;
with the project's profile (50 ms heartbeat, 4 MiB socket buffers) in none of 18
(docs/reliability.md, "Reliable samples under load"). ``FASTDDS_DEFAULT_PROFILES_FILE=
make stress`` runs it without the profile.
"""
import re
import subprocess
import sys

import numpy as np
import pytest

from adcs_launch import control_scenario, start_adcs

from adcs_nodes.bag import header_stamp_ns, read_messages  # noqa: E402

RUNS = 3
BURNERS = 3
DURATION_S = 8000
GRID_S = 2.0                     # the magnetometer's (and so the commands') period [s]
TOPICS = ('/adcs/attitude_estimate', '/adcs/actuator_command')


@pytest.mark.slow
def test_three_recorded_runs_beside_cpu_burners_lose_nothing(tmp_path):
    scenario = control_scenario(tmp_path)            # 2 s magnetometer, 1 s input timeout
    burners = [subprocess.Popen([sys.executable, '-c', 'while True: pass'])
               for _ in range(BURNERS)]
    procs = []
    try:
        for i in range(RUNS):
            procs.append(start_adcs('run', scenario, '--record', str(tmp_path / f'bag{i}'),
                                    '--duration', str(DURATION_S), '--quiet'))
        outputs = [p.communicate(timeout=900) for p in procs]
    finally:
        for p in procs + burners:
            if p.poll() is None:
                p.kill()
                p.wait(timeout=60)
    for i, (proc, (out, err)) in enumerate(zip(procs, outputs)):
        text = out + err
        assert proc.returncode == 0, text
        missed = re.findall(r'wall \(.*\), missed frames (\d+)', text)
        assert missed == ['0'], text
        assert 'bag misses' not in text, text
        for topic in TOPICS:
            stamps = np.array([header_stamp_ns(m) for _, _, m in
                               read_messages(str(tmp_path / f'bag{i}'), [topic])]) / 1e9
            gaps = np.flatnonzero(~np.isclose(np.diff(stamps), GRID_S))
            assert len(stamps) == DURATION_S / GRID_S + 1 and len(gaps) == 0, \
                (i, topic, len(stamps), stamps[gaps][:5])
