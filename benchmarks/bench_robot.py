"""Robot kinematics benchmark: Katana tool position + position Jacobian, and the damped pinv.

Run: ``.venv/bin/python benchmarks/bench_robot.py``

Peer, measured in the same run: a plain numpy implementation of the same kinematics (one 4x4
homogeneous transform per joint, a Python loop over joints, the geometric Jacobian from cross
products), called in a loop over the batch; and ``np.linalg.pinv`` for the pseudo-inverse.
Times are medians over repeats; BLAS is limited to one thread.
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from pbdkit import robots
from pbdkit.robots._kinematics import damped_pinv

PI = math.pi

# design.md's Katana numbers: joint origins (xyz, rpy), all joints about local z; fixed tool frame
ORIGINS = [
    ((0, 0, 0.2015), (0, 0, 0)),
    ((0, 0, 0), (PI / 2, 0, 0)),
    ((0.19, 0, 0), (0, 0, 0)),
    ((0.139, 0, 0), (PI, 0, 0)),
    ((0.1523, 0, 0), (PI / 2, 0, -PI / 2)),
]
TOOL = ((0, 0, -0.1505), (0, PI / 2, 0))


def homogeneous(xyz: tuple[float, ...], rpy: tuple[float, ...]) -> NDArray[np.float64]:
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = (
        math.cos(r),
        math.sin(r),
        math.cos(p),
        math.sin(p),
        math.cos(y),
        math.sin(y),
    )
    t = np.eye(4)
    t[:3, :3] = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    t[:3, 3] = xyz
    return t


PEER_ORIGINS = [homogeneous(xyz, rpy) for xyz, rpy in ORIGINS]
PEER_TOOL = homogeneous(*TOOL)


def peer_fk_jacobian(q: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Plain numpy: T = prod_i (origin_i Rz(q_i)) tool; column i = z_i x (x - p_i)."""
    t = np.eye(4)
    axes, points = [], []
    for origin, qi in zip(PEER_ORIGINS, q, strict=True):
        c, s = math.cos(qi), math.sin(qi)
        rz = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
        t = t @ origin @ rz
        axes.append(t[:3, 2])
        points.append(t[:3, 3])
    x = (t @ PEER_TOOL)[:3, 3]
    jac = np.empty((3, len(axes)))
    for i, (a, p) in enumerate(zip(axes, points, strict=True)):
        d = x - p  # a x d, written out (np.cross is slow on 3-vectors)
        jac[:, i] = (
            a[1] * d[2] - a[2] * d[1],
            a[2] * d[0] - a[0] * d[2],
            a[0] * d[1] - a[1] * d[0],
        )
    return x, jac


def peer_fk(q: NDArray[np.float64]) -> NDArray[np.float64]:
    t = np.eye(4)
    for origin, qi in zip(PEER_ORIGINS, q, strict=True):
        c, s = math.cos(qi), math.sin(qi)
        t = t @ origin @ np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    result: NDArray[np.float64] = (t @ PEER_TOOL)[:3, 3]
    return result


def median_time(fn: Callable[[], object], number: int, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(number):
            fn()
        times.append((time.perf_counter() - start) / number)
    return statistics.median(times)


def fmt(seconds: float) -> str:
    return f"{seconds * 1e6:.1f} us" if seconds < 1e-3 else f"{seconds * 1e3:.2f} ms"


def main() -> None:
    katana = robots.katana()
    rng = np.random.default_rng(0)
    q_batch = rng.uniform(katana.lower, katana.upper, size=(1000, 5))
    q = q_batch[0]

    # the peer computes the same thing
    x_b, j_b = katana.fk_jacobian(q_batch)
    peer = [peer_fk_jacobian(qi) for qi in q_batch]
    assert np.allclose(x_b, [p[0] for p in peer], rtol=0, atol=1e-12)
    assert np.allclose(j_b, [p[1] for p in peer], rtol=0, atol=1e-12)
    assert np.allclose(katana.fk(q), peer_fk(q), rtol=0, atol=1e-12)
    jac = katana.jacobian(q)
    assert np.allclose(damped_pinv(jac), np.linalg.pinv(jac), rtol=0, atol=1e-12)

    rows = [
        (
            "fk + jacobian, 1 config",
            median_time(lambda: katana.fk_jacobian(q), 2000, 9),
            median_time(lambda: peer_fk_jacobian(q), 500, 9),
            "<= 10 us",
        ),
        (
            "fk + jacobian, batch of 1000",
            median_time(lambda: katana.fk_jacobian(q_batch), 10, 9),
            median_time(lambda: [peer_fk_jacobian(qi) for qi in q_batch], 1, 5),
            "<= 5 ms",
        ),
        (
            "fk only, 1 config",
            median_time(lambda: katana.fk(q), 2000, 9),
            median_time(lambda: peer_fk(q), 500, 9),
            "",
        ),
        (
            "damped_pinv 3x5 (peer np.linalg.pinv)",
            median_time(lambda: damped_pinv(jac), 2000, 9),
            median_time(lambda: np.linalg.pinv(jac), 2000, 9),
            "",
        ),
        (
            "damped_pinv batch 1000x3x5",
            median_time(lambda: damped_pinv(j_b), 10, 9),
            median_time(lambda: np.linalg.pinv(j_b), 5, 5),
            "",
        ),
    ]
    print("Katana 6M180 (5 joints), median times; ratio = peer / pbdkit")
    header = f"| {'operation':<38} | {'pbdkit':>9} | {'peer':>9} | {'ratio':>6} | {'target':<8} |"
    print(header)
    print("|" + "|".join("-" * (len(c)) for c in header.split("|")[1:-1]) + "|")
    for name, ours, theirs, target in rows:
        ratio = f"{theirs / ours:.1f}x"
        print(f"| {name:<38} | {fmt(ours):>9} | {fmt(theirs):>9} | {ratio:>6} | {target:<8} |")


if __name__ == "__main__":
    with threadpool_limits(limits=1):
        main()
