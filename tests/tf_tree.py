"""tf2's lookup, done by hand, and the bound on its interpolation error: shared by the tests of the tf
tree in logs (``tests/pipelines/test_ros2_conventions.py``) and on live streams
(``tests/pipelines/test_live_tf.py``).

Quaternions are (w, x, y, z), unit, turning child-frame vectors into the parent frame.
"""

import numpy as np

EPS = np.finfo(float).eps


def quat_mul(a, b):
    """Hamilton product ``a ⊗ b`` of (..., 4) arrays."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_angle(a, b):
    """Rotation angle between unit quaternions, rad (sign-free; atan2 keeps small angles exact)."""
    d = quat_mul(a * np.array([1.0, -1.0, -1.0, -1.0]), b)
    return 2 * np.arctan2(np.linalg.norm(d[..., 1:], axis=-1), np.abs(d[..., 0]))


def slerp(q0, q1, s):
    """tf2's interpolation of rotations (shortest arc)."""
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    small = theta < 1e-12
    sin = np.where(small, 1.0, np.sin(theta))
    w0 = np.where(small, 1 - s, np.sin((1 - s) * theta) / sin)
    w1 = np.where(small, s, np.sin(s * theta) / sin)
    return w0 * q0 + w1 * q1


def tf_lookup(tf_ns, tf_q, tf_p, stamps):
    """tf2's ``lookupTransform`` of one edge at ``stamps`` (M,) ns from its transforms at ``tf_ns`` (K,)
    ascending, ``tf_q`` (K, 4), ``tf_p`` (K, 3): the neighbours' slerp and linear interpolation.
    ``AssertionError`` for a stamp outside ``tf_ns`` (tf2 refuses to extrapolate). Returns ``(q (M, 4), p (M, 3))``."""
    tf_ns, stamps = np.asarray(tf_ns), np.asarray(stamps)
    assert stamps.min() >= tf_ns[0] and stamps.max() <= tf_ns[-1], "a stamp outside the tree's span"
    j = np.clip(np.searchsorted(tf_ns, stamps, side="right") - 1, 0, len(tf_ns) - 2)
    s = ((stamps - tf_ns[j]) / (tf_ns[j + 1] - tf_ns[j]))[:, None]
    return slerp(tf_q[j], tf_q[j + 1], s), (1 - s) * tf_p[j] + s * tf_p[j + 1]


def interpolation_bound(stamps, tf_ns, true_w, true_p=None):
    """The bound on tf2's interpolation error between stamps at most ``h`` apart (``frames.py``'s notes):
    ``h²/8 · (|ω̇| + h|ω|(|ω̇| + |ω|²))`` rad for the rotation and ``h²/8 · |p̈|`` m for the position,
    with ``|ω̇|``, ``|p̈|`` the truth's largest finite differences at ``stamps`` times 1.5 (a difference
    quotient underestimates a peak), plus round-off. ``true_w`` (M, 3) rad/s and ``true_p`` (M, 3) m at
    ``stamps`` (M,) ns. Returns ``(bound_q, bound_p)`` (``bound_p`` None without ``true_p``)."""
    t = (np.asarray(stamps) - stamps[0]) * 1e-9
    h = np.diff(tf_ns).max() * 1e-9
    w_max = np.linalg.norm(true_w, axis=1).max()
    w_dot = np.linalg.norm(np.gradient(true_w, t, axis=0), axis=1).max() * 1.5
    bound_q = h**2 / 8 * (w_dot + h * w_max * (w_dot + w_max**2)) + 100 * EPS
    if true_p is None:
        return bound_q, None
    accel = np.linalg.norm(np.gradient(np.gradient(true_p, t, axis=0), t, axis=0), axis=1).max() * 1.5
    return bound_q, h**2 / 8 * accel + 100 * EPS * np.abs(true_p).max()
