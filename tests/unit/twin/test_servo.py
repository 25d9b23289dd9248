"""The twin's joint servo model (flexsheet.twin.servo): rate and acceleration limits, convergence, the stated
first-order lag."""

import numpy as np

from flexsheet.arm.kinematics import Q_HOME
from flexsheet.twin.servo import JointServo, ServoParams

T = 0.0071


def test_servo_respects_rate_accel_and_converges():
    p = ServoParams()
    s = JointServo(Q_HOME, p)
    goal = Q_HOME + np.array([0.5, 0.3, -0.3, 1.0, 0.5, -2.0])
    v_prev = np.zeros(6)
    for _ in range(700):
        s.step(goal, T)
        assert np.all(np.abs(s.v) <= p.qd_max * (1 + 1e-12))
        assert np.all(np.abs(s.v - v_prev) <= p.qdd_max * T + 1e-9)
        v_prev = s.v.copy()
    assert np.max(np.abs(s.q - goal)) < 1e-4


def test_servo_ramp_lag_is_tau_times_speed():
    p = ServoParams(tau=0.02)
    s = JointServo(Q_HOME, p)
    speed = 0.2    # rad/s, well below the limits
    t = 0.0
    for _ in range(300):
        t += T
        s.step(Q_HOME + speed * t, T)
    lag = (Q_HOME + speed * t) - s.q
    # explicit-Euler first-order lag: after a step the lag is v·(tau − T) (v·tau against the previous target)
    assert np.allclose(lag, speed * (p.tau - T), rtol=0.02)
