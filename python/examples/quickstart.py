"""Quickstart: the paper's main result from Python.

Optimise the flicking finger from rest (full second-order DDP, the paper's task), build a controller
library, run its global policy in closed loop, and plot the ellipse's angle theta3 over time and the
finger's cycle in configuration space (theta1, theta2), coloured by contact impulse.

    pip install ./python matplotlib
    python python/examples/quickstart.py            # the default library (about 15 s to build)
    python python/examples/quickstart.py --quick    # a small library, seconds

Writes results/quickstart.png (or --out).
"""

import argparse
import pathlib
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import slcp  # noqa: E402


def main(argv=None):
    p = argparse.ArgumentParser(description="the paper's main figure from Python")
    p.add_argument("--quick", action="store_true", help="a small library (seconds) instead of the default")
    p.add_argument("--seconds", type=float, default=60.0, help="simulated seconds of closed loop")
    p.add_argument("--out", default="results/quickstart.png")
    args = p.parse_args(argv)

    # 1. Optimise from rest: the paper's task (-theta3 + 0.05 |u|^2, logistic sigma = 0.1, N = 75).
    t = time.perf_counter()
    sol = slcp.optimize()
    print(
        f"optimised from rest: {sol['passes']} passes, cost {sol['cost']:.3f}, {sol['status']}, "
        f"theta3 {sol['states'][-1, 2]:.2f} rad after 3.75 s ({time.perf_counter() - t:.2f} s)"
    )

    # 2. A library of local controllers (paper IV-C) and its nearest-neighbour policy.
    t = time.perf_counter()
    if args.quick:
        lib = slcp.Library.train(trajectories=60, trunk=40, settle=10, length=5, growth=0)
    else:
        lib = slcp.Library.train()
    print(f"library: {len(lib)} controllers in {time.perf_counter() - t:.1f} s")

    # 3. The policy in closed loop on the smoothed system, from the finger at rest.
    sim = slcp.Simulator()
    x = lib.x0
    xs, impulses = [x], [0.0]
    for _ in range(int(round(args.seconds / sim.h))):
        info = sim.step_info(x, lib.policy(x))
        x = info["x_next"]
        xs.append(x)
        impulses.append(float(info["normal_impulse"].sum()))
    xs, impulses = np.array(xs), np.array(impulses)
    time_axis = np.arange(len(xs)) * sim.h
    last = len(xs) // 4
    rate = (xs[-1, 2] - xs[-last, 2]) / (time_axis[-1] - time_axis[-last])
    print(f"closed loop: theta3 turned {xs[-1, 2]:.1f} rad in {args.seconds:.0f} s, {rate:.2f} rad/s over the last quarter")

    # 4. The figure: theta3 over time, and the last 20 s in (theta1, theta2) coloured by impulse.
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    a.plot(time_axis, xs[:, 2], color="tab:blue")
    a.set_xlabel("t (s)")
    a.set_ylabel("theta3 (rad)")
    a.set_title(f"the ellipse spun by the library's policy ({rate:.2f} rad/s at the end)")
    tail = time_axis >= time_axis[-1] - 20.0
    sc = b.scatter(xs[tail, 0], xs[tail, 1], c=impulses[tail], s=6, cmap="coolwarm")
    b.plot(xs[tail, 0], xs[tail, 1], color="0.8", lw=0.5, zorder=0)
    b.set_xlabel("theta1 (rad)")
    b.set_ylabel("theta2 (rad)")
    b.set_title("the finger's cycle, last 20 s")
    fig.colorbar(sc, ax=b, label="contact impulse")
    fig.tight_layout()
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")
    return xs, rate


if __name__ == "__main__":
    main()
