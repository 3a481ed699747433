"""A lifecycle cleanup and configure of B-dot during a lockstep run (issue 37, item 5).

As a user meets it: ``adcs run`` of paper000_control (one process per node, paced so the run
lasts long enough to type), then what ``ros2 lifecycle set /bdot_controller deactivate``,
``cleanup``, ``configure`` and ``activate`` send (the standard ``change_state`` service, from
a separate process on the run's domain). Before, B-dot restarted its frames at t = 0 while the
world was far on, and the manager dropped its commands as coming from a foreign publisher
(its new GID) with nothing said. Now the node rejoins at the world's frame, and the manager
locks to the re-created publisher and says so on ``/diagnostics`` (``relocks``,
``last_relock``).
"""
import os
import subprocess
import sys

from adcs_launch import ROOT, control_scenario, latest_run_dir, node_log, start_adcs, \
    wait_manifest
from adcs_nodes.bag import header_stamp_ns, read_messages

S = 10**9
#: The transitions, as ``ros2 lifecycle set`` is called once each, after sim time AT_S.
LIFECYCLE = """
import sys, time
import rclpy
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
from rosgraph_msgs.msg import Clock

rclpy.init()
node = rclpy.create_node('lifecycle_cli')
seen = []
node.create_subscription(Clock, '/clock', lambda m: seen.append(m.clock.sec), 10)
client = node.create_client(ChangeState, '/bdot_controller/change_state')
deadline = time.monotonic() + 120.0
while (not seen or seen[-1] - seen[0] < float(sys.argv[1])) and time.monotonic() < deadline:
    rclpy.spin_once(node, timeout_sec=0.05)
assert seen, 'no /clock'
for label in ('deactivate', 'cleanup', 'configure', 'activate'):
    request = ChangeState.Request()
    request.transition.id = getattr(Transition, 'TRANSITION_' + label.upper())
    assert client.wait_for_service(timeout_sec=30.0)
    future = client.call_async(request)
    rclpy.spin_until_future_complete(node, future, timeout_sec=30.0)
    assert future.done() and future.result().success, label
    print(label, seen[-1] - seen[0], flush=True)
"""


def test_bdot_cleaned_up_and_configured_during_a_run_rejoins_at_the_worlds_frame(tmp_path):
    from adcs_nodes.tools.run.launcher import child_env
    scenario = control_scenario(tmp_path, duration_s=400.0)
    bag = str(tmp_path / 'bag')
    proc = start_adcs('run', scenario, '--record', bag, '--rate', '20', '--quiet')
    cli = None
    try:
        manifest = wait_manifest(proc)
        cli = subprocess.run([sys.executable, '-c', LIFECYCLE, '100'], cwd=ROOT,
                             env=child_env(manifest['domain']), capture_output=True, text=True,
                             timeout=240)
        out, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert cli.returncode == 0, (cli.stdout + cli.stderr
                                 + node_log(latest_run_dir(), 'bdot_controller')[-3000:])
    assert proc.returncode in (0, 3), out + err     # 3: degraded by the frames B-dot missed
    run_dir = latest_run_dir()
    log = node_log(run_dir, 'bdot_controller')
    assert 'joined the run at t=' in log, log[-3000:]
    # B-dot's commands: on the 2 s grid, never restarted at 0, and again to the end
    stamps = [header_stamp_ns(m) for _, _, m in
              read_messages(bag, ['/adcs/controllers/bdot/command'])]
    t0 = min(header_stamp_ns(m) for _, _, m in read_messages(bag, ['/sim/state']))
    elapsed = [(s - t0) // S for s in stamps]
    assert elapsed == sorted(set(elapsed)), 'B-dot frames went back in time'
    assert all(e % 2 == 0 for e in elapsed)
    gaps = [(a, b) for a, b in zip(elapsed, elapsed[1:]) if b - a > 2]
    assert len(gaps) == 1 and gaps[0][0] >= 50, gaps           # the time it was away
    assert elapsed[-1] >= 398, elapsed[-5:]
    # the manager took the new publisher and said so; nothing dropped as foreign
    last = {}
    for _, _, m in read_messages(bag, ['/diagnostics']):
        for st in m.status:
            if st.name == 'controller_manager':
                last = {kv.key: kv.value for kv in st.values}
    assert last.get('relocks') == '1', last
    assert 'bdot_controller re-created its publisher' in last.get('last_relock', ''), last
    assert last.get('security_foreign_publisher') == '0', last
    assert os.path.isdir(run_dir)
