"""The unicycle benchmark of docs/benchmarks.md ("Optimiser") solved by crocoddyl, for a comparison in the
same run: x0 = [-1, -1, 1], dt = 0.1, T = 75, crocoddyl's ActionModelUnicycle with cost weights [10, 1]
(running cost 50 |x|^2 + 0.5 |u|^2, final 50 |x_T|^2), zero initial controls. Prints one JSON line per
solver: iterations, final cost, median solve time over `repeats` solves (ms).

`cargo xtask benchmarks --only ddp` runs it when `python3 -c "import crocoddyl"` works
(`pip install crocoddyl`); nothing in the tests needs it.
"""

import json
import sys
import time

import crocoddyl
import numpy as np


def problem():
    model = crocoddyl.ActionModelUnicycle()
    model.costWeights = np.array([10.0, 1.0])
    model.dt = 0.1
    x0 = np.array([-1.0, -1.0, 1.0])
    shooting = crocoddyl.ShootingProblem(x0, [model] * 75, model)
    # One thread, as ours (crocoddyl's OpenMP threads spin against a busy core: 0.5 ms becomes 150 ms).
    shooting.nthreads = 1
    return shooting


def run(name, make, repeats):
    times, iters, cost = [], None, None
    for _ in range(repeats):
        solver = make(problem())
        start = time.perf_counter()
        solver.solve([], [], 1000)
        times.append(time.perf_counter() - start)
        iters, cost = solver.iter, solver.cost
    times.sort()
    print(json.dumps({"solver": name, "iterations": iters, "cost": cost,
                      "ms": 1e3 * times[len(times) // 2], "version": crocoddyl.__version__}))


if __name__ == "__main__":
    repeats = int(sys.argv[1]) if len(sys.argv) > 1 else 21
    run("DDP", crocoddyl.SolverDDP, repeats)
    run("FDDP", crocoddyl.SolverFDDP, repeats)
