"""CSV export and report on a synthetic bag written with rosbags (no ROS graph needed).

Truth is analytic: the body turns about the fixed unit axis a = (1, 2, 2)/3 relative to the
orbit frame with angle theta(t) = 10 deg + 0.5 deg/s * t, so q_orbit_body(t) =
[sin(theta/2) a, cos(theta/2)] and the angle to the orbit frame at t = 99 s is 59.5 deg.
The estimate is the truth turned by 2 deg about body z. Log times are deliberately offset and
jittered against the header stamps: the tools must use header stamps.
"""
import csv
import math
import random

import numpy as np
import pytest

pytest.importorskip('rosbags')

from rosbags.rosbag2 import StoragePlugin, Writer  # noqa: E402

from adcs_nodes.bag import make_typestore, read_messages  # noqa: E402
from bag_digest import content_digest, topic_summary  # noqa: E402
from adcs_nodes.tools.analyse.export import export_csv, topic_file_name  # noqa: E402
from adcs_nodes.tools.analyse.report import make_report  # noqa: E402

EPOCH_S = 1_704_067_200  # 2024-01-01T00:00:00Z
N = 100
AXIS = np.array([1.0, 2.0, 2.0]) / 3.0
THETA0 = math.radians(10.0)
RATE = math.radians(0.5)
EST_ERR = math.radians(2.0)
ORBIT_RATE = 2.0 * math.pi / 5400.0


def theta(k: int) -> float:
    return THETA0 + RATE * k


def q_axis_angle(axis, angle):
    return [*(math.sin(angle / 2.0) * np.asarray(axis)), math.cos(angle / 2.0)]


def hamilton(p, q):
    px, py, pz, pw = p
    qx, qy, qz, qw = q
    return [pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
            pw * qw - px * qx - py * qy - pz * qz]


def b_eci(k: int):
    return [2.0e-5 * math.cos(k / 20.0), -1.0e-5, 3.0e-5 * math.sin(k / 20.0)]


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    path = tmp_path_factory.mktemp('synthetic') / 'run'
    store = make_typestore()
    T = store.types
    rng = random.Random(7)

    def header(k, frame):
        return T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](
            sec=EPOCH_S + k, nanosec=0), frame_id=frame)

    def quat(q):
        return T['geometry_msgs/msg/Quaternion'](x=q[0], y=q[1], z=q[2], w=q[3])

    def vec(v):
        return T['geometry_msgs/msg/Vector3'](x=v[0], y=v[1], z=v[2])

    with Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        types = {'/sim/state': 'adcs_msgs/msg/AttitudeState',
                 '/sim/environment': 'adcs_msgs/msg/Environment',
                 '/adcs/attitude_estimate': 'adcs_msgs/msg/AttitudeState',
                 '/sim/wheels': 'adcs_msgs/msg/WheelState',
                 '/adcs/filter_diagnostics': 'adcs_msgs/msg/FilterDiagnostics',
                 '/chatter': 'std_msgs/msg/String'}
        conns = {t: writer.add_connection(t, m, typestore=store) for t, m in types.items()}

        def write(topic, k, msg):
            log_ns = (EPOCH_S + 5000 + k) * 10**9 + rng.randrange(0, 400_000_000)
            writer.write(conns[topic], log_ns, store.serialize_cdr(msg, types[topic]))

        w_body = list(AXIS * RATE)
        for k in range(N):
            q = q_axis_angle(AXIS, theta(k))
            write('/sim/environment', k, T['adcs_msgs/msg/Environment'](
                header=header(k, 'eci'), r_eci=vec([7.0e6, 0.0, 0.0]),
                v_eci=vec([0.0, 7.5e3, 0.0]), q_eci_orbit=quat([0.0, 0.0, 0.0, 1.0]),
                omega_orbit_eci_eci=vec([0.0, 0.0, 0.0]), orbit_rate=ORBIT_RATE,
                argument_of_latitude=ORBIT_RATE * k, b_eci=vec(b_eci(k)),
                b_dot_eci=vec([0.0, 0.0, 0.0]), q_eci_ecef=quat([0.0, 0.0, 0.0, 1.0])))
            state = T['adcs_msgs/msg/AttitudeState'](
                header=header(k, 'body'), q_eci_body=quat(q), q_orbit_body=quat(q),
                omega_body_eci_body=vec(w_body), omega_body_orbit_body=vec(w_body),
                covariance=np.zeros(36))
            write('/sim/state', k, state)
            q_est = hamilton(q, q_axis_angle([0.0, 0.0, 1.0], EST_ERR))
            write('/adcs/attitude_estimate', k, T['adcs_msgs/msg/AttitudeState'](
                header=header(k, 'body'), q_eci_body=quat(q_est), q_orbit_body=quat(q_est),
                omega_body_eci_body=vec(w_body), omega_body_orbit_body=vec(w_body),
                covariance=np.full(36, 0.5)))
            write('/sim/wheels', k, T['adcs_msgs/msg/WheelState'](
                header=header(k, 'body'), names=['wx', 'wy', 'wz'],
                momentum=np.array([0.001 * k, -0.002 * k, 0.0]), speed=np.zeros(3),
                torque=np.zeros(3), h_wheels_body=vec([0.001 * k, -0.002 * k, 0.0])))
            write('/adcs/filter_diagnostics', k, T['adcs_msgs/msg/FilterDiagnostics'](
                header=header(k, 'body'), algorithm='test',
                innovation=np.arange(k % 3 + 1, dtype=float) + k, covariance_trace=1.0 / (k + 1),
                update_count=k, rejected_count=0, last_rejection=''))
            if k < 5:
                write('/chatter', k, T['std_msgs/msg/String'](data=f'hello, "{k}"'))
    return path


def read_csv(path):
    with open(path, newline='', encoding='utf-8') as handle:
        rows = list(csv.reader(handle))
    return rows[0], rows[1:]


def test_topic_summary_and_reading(bag):
    summary = topic_summary(bag)
    assert summary['/sim/state'][:2] == ('adcs_msgs/msg/AttitudeState', N)
    assert summary['/chatter'][:2] == ('std_msgs/msg/String', 5)
    states = [m for _, _, m in read_messages(bag, ['/sim/state'])]
    assert [m.header.stamp.sec for m in states] == [EPOCH_S + k for k in range(N)]
    digest = content_digest(bag)
    assert digest['/sim/state'][0] == N and len(digest['/sim/state'][1]) == 64


def test_export_csv_columns_and_values(bag, tmp_path):
    files = export_csv(bag, tmp_path / 'csv')
    names = sorted(p.name for p in files)
    assert names == ['adcs__attitude_estimate.csv', 'adcs__filter_diagnostics.csv',
                     'chatter.csv', 'sim__environment.csv', 'sim__state.csv', 'sim__wheels.csv']
    assert topic_file_name('/sim/state') == 'sim__state.csv'

    cols, rows = read_csv(tmp_path / 'csv' / 'sim__state.csv')
    assert cols[0] == 't'
    assert not any(c.startswith('header.stamp') for c in cols)
    assert cols[1:10] == ['header.frame_id', 'q_eci_body.x', 'q_eci_body.y', 'q_eci_body.z',
                          'q_eci_body.w', 'q_orbit_body.x', 'q_orbit_body.y',
                          'q_orbit_body.z', 'q_orbit_body.w']
    assert cols[-36:] == [f'covariance[{i}]' for i in range(36)]
    assert len(rows) == N
    for k in (0, 37, N - 1):
        row = dict(zip(cols, rows[k]))
        assert float(row['t']) == pytest.approx(EPOCH_S + k, abs=1e-6)
        q = q_axis_angle(AXIS, theta(k))
        assert float(row['q_orbit_body.w']) == q[3]  # exact round trip
        assert float(row['q_orbit_body.y']) == q[1]
        assert float(row['omega_body_eci_body.z']) == AXIS[2] * RATE

    cols, rows = read_csv(tmp_path / 'csv' / 'sim__environment.csv')
    row = dict(zip(cols, rows[50]))
    assert [float(row[f'b_eci.{c}']) for c in 'xyz'] == b_eci(50)
    assert 'r_eci.x' in cols and 'q_eci_ecef.w' in cols

    # variable arrays: as many columns as the longest array, in index order, blanks when short
    cols, rows = read_csv(tmp_path / 'csv' / 'adcs__filter_diagnostics.csv')
    i0 = cols.index('innovation[0]')
    assert cols[i0:i0 + 3] == ['innovation[0]', 'innovation[1]', 'innovation[2]']
    assert 'innovation[3]' not in cols
    first = dict(zip(cols, rows[0]))
    assert first['innovation[0]'] == '0.0' and first['innovation[1]'] == ''
    third = dict(zip(cols, rows[2]))
    assert [float(third[f'innovation[{i}]']) for i in range(3)] == [2.0, 3.0, 4.0]

    # no header: t is the log time, strings survive quoting
    cols, rows = read_csv(tmp_path / 'csv' / 'chatter.csv')
    assert cols == ['t', 'data']
    assert [r[1] for r in rows] == [f'hello, "{k}"' for k in range(5)]
    assert EPOCH_S + 5000 <= float(rows[0][0]) < EPOCH_S + 5001


def test_report_metrics_plots_and_summary(bag, tmp_path):
    out = tmp_path / 'report'
    metrics = make_report(bag, out)
    truth_final = math.degrees(theta(N - 1))  # 59.5 deg, independent of the code under test
    assert metrics['final_angle_orbit_deg'] == pytest.approx(truth_final, abs=1e-9)
    assert metrics['max_angle_orbit_deg'] == pytest.approx(truth_final, abs=1e-9)
    assert metrics['max_rate_deg_s'] == pytest.approx(0.5, abs=1e-12)
    assert metrics['final_rate_orbit_deg_s'] == pytest.approx(0.5, abs=1e-12)
    assert metrics['estimate_final_error_deg'] == pytest.approx(2.0, abs=1e-9)
    assert metrics['estimate_max_error_deg'] == pytest.approx(2.0, abs=1e-9)
    assert metrics['estimate_matched'] == N
    assert metrics['wheel_max_abs_momentum_Nms'] == pytest.approx(0.002 * (N - 1))
    norms = [np.linalg.norm(b_eci(k)) * 1e6 for k in range(N)]
    assert metrics['field_mean_norm_uT'] == pytest.approx(np.mean(norms))
    assert metrics['duration_s'] == pytest.approx(N - 1)
    assert metrics['orbit_period_s'] == pytest.approx(5400.0)
    assert metrics['start_utc'].startswith('2024-01-01 00:00:00')
    # rates from header stamps (exactly 1 Hz), not from the jittered log times
    assert metrics['topics']['/sim/state']['rate_hz'] == pytest.approx(1.0, abs=1e-12)
    assert metrics['topics']['/sim/state']['count'] == N
    assert metrics['topics']['/chatter']['rate_source'] == 'log_time'
    for name in ('attitude.png', 'rates.png', 'field.png', 'wheels.png', 'estimate_error.png'):
        assert name in metrics['plots']
        data = (out / name).read_bytes()
        assert data.startswith(b'\x89PNG') and len(data) > 5000
    text = (out / 'summary.md').read_text()
    assert '| `/sim/state` | `adcs_msgs/msg/AttitudeState` | 100 | 1 |' in text
    assert '## Paper comparison' in text and '_No paper comparison for this run._' in text
    assert '59.5' in text
    assert metrics['all_pass'] is None and metrics['expectations'] == []
    assert (out / 'metrics.json').is_file()

    again = make_report(bag, tmp_path / 'report2', expectations=[
        ('final pointing error', '< 60 deg', metrics['final_angle_orbit_deg'], True),
        ('settling time', '25.73 s', 31.0, False)])
    text = (tmp_path / 'report2' / 'summary.md').read_text()
    assert '| final pointing error | < 60 deg | 59.5 | PASS |' in text
    assert '| settling time | 25.73 s | 31 | FAIL |' in text
    assert again['all_pass'] is False

    # a row without a paper value is information: printed 'info', never counted as a pass
    info = make_report(bag, tmp_path / 'report3', sections=[('Extra', 'hello table')],
                       expectations=[('final pointing error', '< 60 deg', 59.5, True),
                                     ('final angle', '(not given)', 59.5, None)])
    text = (tmp_path / 'report3' / 'summary.md').read_text()
    assert '| final angle | (not given) | 59.5 | info |' in text
    assert '1 of 1 comparisons with the paper pass; 1 rows are information' in text
    assert '## Extra' in text and 'hello table' in text
    assert info['all_pass'] is True
    assert info['expectations'][1]['pass'] is None
    only_info = make_report(bag, tmp_path / 'report4',
                            expectations=[('final angle', '(not given)', 59.5, None)])
    assert only_info['all_pass'] is None

    # a paper claim the run cannot check: printed with its reason, never counted as a pass
    from adcs_nodes.tools.analyse.papers import NotComparable
    nc = make_report(bag, tmp_path / 'report5', expectations=[
        ('final pointing error', '< 60 deg', 59.5, True),
        ('ratio to the reference', '1.5x', '0.66x', NotComparable('reference undescribed'))])
    text = (tmp_path / 'report5' / 'summary.md').read_text()
    assert '| ratio to the reference | 1.5x | 0.66x | not comparable: reference undescribed |' \
        in text
    assert '1 of 1 comparisons with the paper pass; 0 rows are information (no paper value); ' \
        '1 not comparable' in text
    assert nc['all_pass'] is True and nc['expectations'][1]['pass'] is None
    assert nc['expectations'][1]['verdict'] == 'not comparable: reference undescribed'


def test_missing_and_corrupt_bags(tmp_path):
    missing = tmp_path / 'nope'
    with pytest.raises(FileNotFoundError, match='nope'):
        export_csv(missing, tmp_path / 'out')
    with pytest.raises(FileNotFoundError, match='nope'):
        make_report(missing, tmp_path / 'out')
    with pytest.raises(FileNotFoundError, match='nope'):
        read_messages(missing)
    assert not (tmp_path / 'out').exists()

    corrupt = tmp_path / 'corrupt'
    corrupt.mkdir()
    (corrupt / 'metadata.yaml').write_text('rosbag2_bagfile_information: [not, a, mapping\n')
    with pytest.raises(ValueError, match='corrupt'):
        export_csv(corrupt, tmp_path / 'out')
    garbage = tmp_path / 'garbage.mcap'
    garbage.write_bytes(b'\x89MCAP0\r\n' + b'\x00' * 64)
    with pytest.raises(ValueError, match='garbage.mcap'):
        make_report(garbage, tmp_path / 'out')


def test_tools_import_without_rclpy():
    """The analysis tools run on a machine without ROS (rosbags, numpy, matplotlib only)."""
    import subprocess
    import sys
    from pathlib import Path
    root = Path(__file__).resolve().parents[2]
    code = ("import sys; sys.modules['rclpy'] = None; sys.path.insert(0, 'adcs_nodes'); "
            "import adcs_nodes.tools.analyse.report, adcs_nodes.tools.analyse.export; "
            "print(len(adcs_nodes.bag.make_typestore().fielddefs))")
    out = subprocess.run([sys.executable, '-c', code], cwd=root, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert int(out.stdout.strip()) > 100


def _small_bag(path, log_offset_s, order, value=1.0):
    store = make_typestore()
    T = store.types
    with Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        env = writer.add_connection('/sim/wheels', 'adcs_msgs/msg/WheelState', typestore=store)
        ready = writer.add_connection('/lockstep/ready', 'std_msgs/msg/String', typestore=store)
        status = writer.add_connection('/lockstep/status', 'adcs_msgs/msg/LockstepStatus',
                                       typestore=store)
        for k in range(5):
            msg = T['adcs_msgs/msg/WheelState'](
                header=T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](
                    sec=EPOCH_S + k, nanosec=0), frame_id='body'),
                names=['w'], momentum=np.array([value * k]), speed=np.zeros(1),
                torque=np.zeros(1), h_wheels_body=T['geometry_msgs/msg/Vector3'](x=0, y=0, z=0))
            t_log = (EPOCH_S + k + log_offset_s) * 10**9
            writer.write(env, t_log, store.serialize_cdr(msg, 'adcs_msgs/msg/WheelState'))
            st = T['adcs_msgs/msg/LockstepStatus'](
                header=msg.header, node='x', frames=k, missed_frames=0, last_missed_input='',
                wall_time=log_offset_s + 0.1 * k, final=False)
            writer.write(status, t_log, store.serialize_cdr(st, 'adcs_msgs/msg/LockstepStatus'))
        for i, name in enumerate(order):
            writer.write(ready, (EPOCH_S + log_offset_s) * 10**9 + i,
                         store.serialize_cdr(T['std_msgs/msg/String'](data=name),
                                             'std_msgs/msg/String'))


def test_content_digest_ignores_log_times_and_publisher_interleaving(tmp_path):
    _small_bag(tmp_path / 'a', 0, ['dynamics', 'environment', 'recorder'])
    _small_bag(tmp_path / 'b', 77, ['recorder', 'dynamics', 'environment'])
    _small_bag(tmp_path / 'c', 0, ['dynamics', 'environment', 'recorder'], value=1.0 + 1e-15)
    a, b, c = (content_digest(tmp_path / x) for x in 'abc')
    assert a == b
    assert '/lockstep/status' not in a  # wall-clock content, excluded by default
    assert a['/sim/wheels'][0] == 5 and a['/lockstep/ready'][0] == 3
    assert c['/sim/wheels'] != a['/sim/wheels'] and c['/lockstep/ready'] == a['/lockstep/ready']
