"""A stranger on a run's ROS domain (test helper, not a test): forged actuator commands.

Started with the run's ``ROS_DOMAIN_ID``; it joins the domain after the run's start handshake
(``--go-on-stdin``: started early, it joins when a line arrives on stdin). On each new
``/clock`` tick t, once each of its publishers is matched to ``--min-subscribers`` readers
(the consumer and the recorder), it publishes on every topic given a valid command (a
dipole inside the magnetorquer limits, source ``forger``) stamped t and one stamped t +
frame (so a forged command of the next frame is already waiting when that frame begins),
for ``--ticks`` ticks or until ``--timeout`` wall seconds. Prints one JSON line: messages
sent per topic, ticks, and its node name. Exit 0.
"""
import argparse
import json
import sys
import time

import rclpy
from geometry_msgs.msg import Vector3
from rclpy.duration import Duration
from rclpy.node import Node
from rosgraph_msgs.msg import Clock

from adcs_msgs.msg import ActuatorCommand
from adcs_nodes.nodes.lockstep_node import QOS_DATA


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--topics', nargs='+', default=['adcs/actuator_command'])
    ap.add_argument('--frame-s', type=float, default=2.0)
    ap.add_argument('--ticks', type=int, default=20)
    ap.add_argument('--dipole', type=float, default=30.0)
    ap.add_argument('--name', default='forger')
    ap.add_argument('--timeout', type=float, default=120.0)
    ap.add_argument('--min-subscribers', type=int, default=2,
                    help='forge only once every topic has this many matched readers')
    ap.add_argument('--go-on-stdin', action='store_true',
                    help='join the domain only when a line arrives on stdin (started early, '
                         'the imports are done when the test says go)')
    args = ap.parse_args(argv)
    if args.go_on_stdin and not sys.stdin.readline():
        return 0                        # the test ended before its go: nothing to forge
    rclpy.init()
    node = Node(args.name)
    pubs = {t: node.create_publisher(ActuatorCommand, t, QOS_DATA) for t in args.topics}
    sent = {t: 0 for t in args.topics}
    state = {'last': None, 'ticks': 0}
    frame_ns = int(round(args.frame_s * 1e9))

    def on_clock(msg: Clock) -> None:
        now = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec
        if now == state['last'] or state['ticks'] >= args.ticks:
            return
        if any(p.get_subscription_count() < args.min_subscribers for p in pubs.values()):
            return      # not matched to the consumers yet: they would never see it
        state['last'] = now
        state['ticks'] += 1
        for t_ns in (now, now + frame_ns):
            cmd = ActuatorCommand()
            cmd.header.stamp.sec, cmd.header.stamp.nanosec = divmod(t_ns, 1_000_000_000)
            d = args.dipole
            cmd.dipole_body = Vector3(x=d, y=-d, z=d)
            cmd.source = 'forger'
            for topic, pub in pubs.items():
                pub.publish(cmd)
                sent[topic] += 1

    node.create_subscription(Clock, '/clock', on_clock, QOS_DATA)
    deadline = time.monotonic() + args.timeout
    try:
        while state['ticks'] < args.ticks and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.05)
        # let the reliable writers deliver what is queued (or give up at the deadline)
        for pub in pubs.values():
            pub.wait_for_all_acked(Duration(seconds=5.0))
    finally:
        print(json.dumps({'sent': sent, 'ticks': state['ticks'], 'name': args.name}),
              flush=True)
        node.destroy_node()
        rclpy.shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
