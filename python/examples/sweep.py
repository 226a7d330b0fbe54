"""Parameter sweeps on Ray: a grid of library builds and closed-loop evaluations as Ray tasks.

Each grid point (scene x library seed x sigma) builds a controller library with `slcp.Library.train` and
runs its policy in closed loop on its own smoothed world and on hard contact; the rows are gathered into
one table, written as CSV and Markdown, with a progress bar as tasks finish.

    python python/examples/sweep.py                         # a local Ray instance on this machine's cores
    python python/examples/sweep.py --address auto          # the cluster this machine belongs to
    python python/examples/sweep.py --address ray://HEAD:10001 --seeds 1-16 --sigmas 0.05,0.1,0.2

On a cluster every node needs the `slcp` package (`pip install ./python`) and, for scene files, the same
paths (or pass paths on a shared file system). See docs/python.md.
"""

import argparse
import csv
import itertools
import math
import pathlib
import sys
import time

import ray

ROOT = pathlib.Path(__file__).resolve().parents[2]


def parse_range(text):
    """`1-8` or `1,3,5` as a list of ints."""
    out = []
    for part in text.split(","):
        if "-" in part:
            lo, hi = part.split("-")
            out.extend(range(int(lo), int(hi) + 1))
        else:
            out.append(int(part))
    return out


def run_point(scene, task, seed, sigma, trajectories, seconds, recipe):
    """One grid point: build, then evaluate on the smoothed and the hard world (no kicks). Runs in a Ray
    worker; imports slcp there."""
    import slcp

    start = time.perf_counter()
    kwargs = dict(trajectories=trajectories, seed=seed, sigma=sigma, **recipe)
    if scene is not None:
        kwargs.update(scene=scene, task=task)
    lib = slcp.Library.train(**kwargs)
    build = time.perf_counter() - start
    rows = []
    for world in ("own", "hard"):
        e = lib.evaluate(seconds=seconds, kick_every=0.0, model=None if world == "own" else "hard")
        rates = e["task"]["rates"]
        targets = [t for t in e["task"]["targets"] if not t["entry"].endswith("velocity")]
        rows.append(
            {
                "scene": pathlib.Path(scene).name if scene else "finger (built in)",
                "seed": seed,
                "sigma": sigma if sigma is not None else "",
                "world": world,
                "controllers": len(lib),
                "build_s": round(build, 2),
                "rate": round(rates[0]["final_rate"], 4) if rates else "",
                "target_distance": round(targets[0]["last"], 4) if targets else "",
                "cost_per_s": round(e["task"]["final_running_cost_per_second"], 4),
                "unconverged": e["unconverged_steps"],
            }
        )
    return rows


def markdown(rows):
    keys = list(rows[0])
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(str(r[k]) for k in keys) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--address", default=None, help="Ray cluster address (default: start a local instance)")
    p.add_argument("--num-cpus", type=int, default=None, help="CPUs of the local instance (default: all)")
    p.add_argument("--scenes", default="", help="comma-separated scene files (default: the finger's built-in task)")
    p.add_argument("--task", default=None, help="the scene files' task (their only one when omitted)")
    p.add_argument("--seeds", default="1-4", help="library seeds, `1-4` or `1,3`")
    p.add_argument("--sigmas", default="", help="comma-separated sigmas of the libraries' model (default: each task's own)")
    p.add_argument("--trajectories", type=int, default=60)
    p.add_argument("--trunk", type=int, default=30)
    p.add_argument("--settle", type=int, default=5)
    p.add_argument("--length", type=int, default=10)
    p.add_argument("--growth", type=int, default=0)
    p.add_argument("--horizon", type=int, default=None)
    p.add_argument("--seconds", type=float, default=40.0, help="simulated seconds per closed loop")
    p.add_argument("--out", default="results/sweep", help="output prefix: PREFIX.csv and PREFIX.md")
    args = p.parse_args(argv)

    scenes = [s for s in args.scenes.split(",") if s] or [None]
    sigmas = [float(s) for s in args.sigmas.split(",") if s] or [None]
    seeds = parse_range(args.seeds)
    recipe = dict(trunk=args.trunk, settle=args.settle, length=args.length, growth=args.growth)
    if args.horizon is not None:
        recipe["horizon"] = args.horizon

    if args.address is None:
        ray.init(num_cpus=args.num_cpus, include_dashboard=False, log_to_driver=False)
    else:
        ray.init(address=args.address, log_to_driver=False)
    task = ray.remote(num_cpus=1)(run_point)
    grid = list(itertools.product(scenes, seeds, sigmas))
    start = time.perf_counter()
    pending = {
        task.remote(scene, args.task, seed, sigma, args.trajectories, args.seconds, recipe): (scene, seed, sigma)
        for scene, seed, sigma in grid
    }
    rows = []
    try:
        from tqdm import tqdm

        bar = tqdm(total=len(grid), unit="point", file=sys.stderr)
    except ImportError:
        bar = None
    while pending:
        done, _ = ray.wait(list(pending), num_returns=1)
        for ref in done:
            pending.pop(ref)
            rows.extend(ray.get(ref))
            if bar is not None:
                bar.update(1)
    if bar is not None:
        bar.close()
    wall = time.perf_counter() - start
    rows.sort(key=lambda r: (r["scene"], str(r["sigma"]), r["seed"], r["world"]))
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out.with_suffix(".csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    busy = sum(r["build_s"] for r in rows if r["world"] == "own")
    text = markdown(rows) + (
        f"\n{len(grid)} grid points on {int(ray.cluster_resources().get('CPU', 0))} CPUs in {wall:.1f} s "
        f"(library builds alone {busy:.1f} s of work).\n"
    )
    out.with_suffix(".md").write_text(text)
    print(text)
    print(f"wrote {out.with_suffix('.csv')} and {out.with_suffix('.md')}")
    ray.shutdown()
    return rows, wall


if __name__ == "__main__":
    main()
