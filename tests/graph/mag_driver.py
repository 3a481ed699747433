"""A magnetometer driver written as a driver author would write one (issue 23's test driver).

It knows nothing of the project but the message types: its own rclpy node, its own QoS
(``--qos best_effort`` or ``reliable``), its own sample schedule off the frame grid
(``--period``, 7.3 s by default), stamps with jitter (``--jitter``, +-20 ms), lost samples
(``--drop``, 5 %), and paper 000's sensor errors (noise 375/25/65 nT per axis, bias
+-120 nT, misalignment (0.6, -0.6, 0.5) deg, LSB 20 nT). It publishes
``sensors/magnetometer`` (``sensor_msgs/MagneticField``, tesla, ``frame_id`` body).

The "hardware" is the simulated world's truth, read as a real driver reads its sensor: the
true attitude (``sim/state``) and field (``sim/environment``) arrive once per world frame;
the field at a sample's time ``s`` between two truth frames is interpolated (attitude: each
end propagated to ``s`` with its own rate, then slerped; field: cubic Hermite with its time
derivative), so the value is the true body field at ``s``. The sample is published as soon as
the truth frame after ``s`` has arrived (a sensor's conversion latency).

``--silent``: the publisher exists (it matches) but never publishes. ``--log FILE``: one line
per scheduled sample, ``<stamp ns> published <matched>`` or ``<stamp ns> dropped``, flushed at
once, where ``matched`` is the number of subscriptions the publisher knew of when it published.
"""
import argparse
import signal
import sys

import numpy as np
import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from scipy.spatial.transform import Rotation, Slerp
from sensor_msgs.msg import MagneticField

from adcs_msgs.msg import AttitudeState, Environment

NOISE_T = np.array([375e-9, 25e-9, 65e-9])
BIAS_T = np.array([120e-9, -120e-9, 120e-9])
MISALIGNMENT_DEG = np.array([0.6, -0.6, 0.5])
LSB_T = 20e-9


def _stamp(h) -> int:
    return h.stamp.sec * 10**9 + h.stamp.nanosec


def _v(v) -> np.ndarray:
    return np.array([v.x, v.y, v.z])


class MagDriver(Node):
    def __init__(self, args) -> None:
        super().__init__('my_magnetometer_driver')
        self.args = args
        self.rng = np.random.default_rng(args.seed)
        reliability = (ReliabilityPolicy.BEST_EFFORT if args.qos == 'best_effort'
                       else ReliabilityPolicy.RELIABLE)
        self.pub = self.create_publisher(
            MagneticField, 'sensors/magnetometer',
            QoSProfile(depth=10, reliability=reliability, history=HistoryPolicy.KEEP_LAST))
        truth_qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(AttitudeState, 'sim/state', self.on_state, truth_qos)
        self.create_subscription(Environment, 'sim/environment', self.on_env, truth_qos)
        self.states = {}           # stamp ns -> (q_eci_body, omega_body_eci_body)
        self.fields = {}           # stamp ns -> (b_eci, b_dot_eci)
        self.t0 = None             # the first truth stamp (the run's start)
        self.next_s = None         # the next sample time [ns, absolute]
        self.misalignment = Rotation.from_rotvec(np.radians(MISALIGNMENT_DEG))
        self.log = open(args.log, 'a', buffering=1) if args.log else None

    def on_state(self, msg) -> None:
        q = msg.q_eci_body
        self.states[_stamp(msg.header)] = (np.array([q.x, q.y, q.z, q.w]),
                                           _v(msg.omega_body_eci_body))
        self.sample()

    def on_env(self, msg) -> None:
        self.fields[_stamp(msg.header)] = (_v(msg.b_eci), _v(msg.b_dot_eci))
        self.sample()

    def sample(self) -> None:
        """Publish every scheduled sample whose enclosing truth frames have both arrived."""
        both = sorted(set(self.states) & set(self.fields))
        if not both:
            return
        if self.t0 is None:
            self.t0 = both[0]
            self.next_s = self.t0 + int(self.args.first * 1e9)
        while True:
            s = self.next_s
            before = [t for t in both if t <= s]
            after = [t for t in both if t > s]
            if not before or not after:
                break
            ta, tb = before[-1], after[0]
            self.emit(s, self.true_field_body(s, ta, tb))
            self.next_s = s + int(round(self.args.period * 1e9))
        for t in [t for t in self.states if t < self.next_s - 10 * 10**9]:
            del self.states[t]
            self.fields.pop(t, None)

    def true_field_body(self, s: int, ta: int, tb: int) -> np.ndarray:
        h = (tb - ta) / 1e9
        tau = (s - ta) / 1e9
        (qa, wa), (qb, wb) = self.states[ta], self.states[tb]
        ra = Rotation.from_quat(qa) * Rotation.from_rotvec(wa * tau)
        rb = Rotation.from_quat(qb) * Rotation.from_rotvec(-wb * (h - tau))
        r = Slerp([0.0, 1.0], Rotation.concatenate([ra, rb]))([tau / h])[0]
        (ba, da), (bb, db) = self.fields[ta], self.fields[tb]
        u = tau / h            # cubic Hermite of the field with its time derivative
        h00, h10 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u
        h01, h11 = -2 * u**3 + 3 * u**2, u**3 - u**2
        b_eci = h00 * ba + h10 * h * da + h01 * bb + h11 * h * db
        return r.inv().apply(b_eci)            # q_eci_body: body = R^T eci

    def emit(self, s: int, b_body: np.ndarray) -> None:
        jitter = int(self.rng.uniform(-self.args.jitter, self.args.jitter) * 1e9)
        stamp = s + jitter
        b = self.misalignment.inv().apply(b_body) + BIAS_T
        b = b + NOISE_T * self.rng.standard_normal(3)
        b = LSB_T * np.round(b / LSB_T)
        lost = self.rng.random() < self.args.drop
        if self.args.silent or lost:
            self.write(stamp, 'dropped')
            return
        m = MagneticField()
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(stamp, 10**9)
        m.header.frame_id = 'body'
        m.magnetic_field.x, m.magnetic_field.y, m.magnetic_field.z = (float(x) for x in b)
        m.magnetic_field_covariance = [float(NOISE_T[0]**2), 0.0, 0.0,
                                       0.0, float(NOISE_T[1]**2), 0.0,
                                       0.0, 0.0, float(NOISE_T[2]**2)]
        matched = self.pub.get_subscription_count()   # readers this writer knows of
        self.pub.publish(m)
        self.write(stamp, 'published', matched)

    def write(self, stamp: int, what: str, *extra: int) -> None:
        if self.log is not None:
            self.log.write(' '.join(map(str, (stamp, what, *extra))) + '\n')


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument('--qos', choices=('best_effort', 'reliable'), default='best_effort')
    p.add_argument('--period', type=float, default=7.3, help='sample period [s of sim time]')
    p.add_argument('--first', type=float, default=0.4, help='first sample after the start [s]')
    p.add_argument('--jitter', type=float, default=0.02, help='stamp jitter, +- [s]')
    p.add_argument('--drop', type=float, default=0.05, help='probability of a lost sample')
    p.add_argument('--seed', type=int, default=7)
    p.add_argument('--silent', action='store_true', help='match, never publish')
    p.add_argument('--log', default='')
    args = p.parse_args(argv)
    rclpy.init()
    node = MagDriver(args)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    try:
        executor.spin()
    except (KeyboardInterrupt, SystemExit, ExternalShutdownException):
        pass                       # Ctrl-C, SIGTERM, or the context shut down by SIGINT
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
