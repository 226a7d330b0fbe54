"""The cost of crossing from Python into the crates: per call, what `slcp.Simulator.step` adds to the
step itself. The same steps (a 2000-step rollout of the finger under random controls, through contact)
run once inside Rust (`rollout`, one call) and once as 2000 Python calls (`step`, `derivatives`), on
simulators in the same warm-start state; the difference per call is the crossing: argument conversion,
the output array, method dispatch. Median of 15 repetitions. Prints a Markdown table (`cargo xtask
benchmarks --only python` puts it in docs/benchmarks.md).
"""

import statistics
import sys
import time

import numpy as np

import slcp

STEPS = 2000
REPEATS = 15


def controls(seed=1):
    rng = np.random.default_rng(seed)
    return rng.normal(0.0, 3.0, (STEPS, 2))


def main():
    us = controls()
    x0 = np.array([-0.7853981633974483, -0.5235987755982989, 0.0, 0.0, 0.0, 0.0])
    xs = slcp.Simulator().rollout(x0, us)
    touching = sum(
        1 for k in range(0, STEPS, 10) if slcp.Simulator().step_info(xs[k], us[k])["normal_impulse"][0] > 1e-3
    )

    def inside():
        sim = slcp.Simulator()
        t = time.perf_counter()
        sim.rollout(x0, us)
        return time.perf_counter() - t

    def calls(method):
        sim = slcp.Simulator()
        f = getattr(sim, method)
        rows = [xs[k] for k in range(STEPS)]
        t = time.perf_counter()
        for k in range(STEPS):
            f(rows[k], us[k])
        return time.perf_counter() - t

    def median(f):
        return statistics.median(f() for _ in range(REPEATS)) / STEPS * 1e6

    rollout = median(inside)
    step = median(lambda: calls("step"))
    derivatives = median(lambda: calls("derivatives"))
    print(
        f"Python {sys.version.split()[0]}, NumPy {np.__version__}: the finger, logistic sigma = 0.1, "
        f"{STEPS} steps of a rollout under random controls (about {100 * touching // (STEPS // 10)}% of them in contact), "
        f"median of {REPEATS}.\n"
    )
    print("| per step | us |\n|---|---:|")
    print(f"| inside Rust (`rollout`, one call) | {rollout:.2f} |")
    print(f"| `step(x, u)` from Python | {step:.2f} |")
    print(f"| crossing per `step` call (difference) | {step - rollout:.2f} |")
    print(f"| `derivatives(x, u)` from Python (step, fx, fu) | {derivatives:.2f} |")


if __name__ == "__main__":
    main()
