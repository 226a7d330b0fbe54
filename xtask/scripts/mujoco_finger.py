"""The flicking finger of docs/SCENE.md (scenes/finger.toml) in MuJoCo, for a comparison of step and
derivative times in the same run as `cargo xtask benchmarks --only dynamics`.

The scene as MuJoCo can hold it: the three ellipses as ellipsoids in the x-y plane (the third semi-axis
the smaller in-plane one), hinges about z with the file's limits and damping, masses and moments of inertia
about z as SCENE.md gives them (density 1: m = pi a b, I = m (a^2 + b^2) / 4), gravity (0, -4, 0), motors
on the two links, the one contact pair (link2, ellipse) with friction 0.5, h = 0.05 and MuJoCo's default
Euler integrator and soft contact. The states: the rollout from x0 under u = [0.3, -0.2], as ours, the steps
at which MuJoCo finds the pair in contact.

Timed, each a median over those states:
- a step (`mj_step`), in C over the whole batch (`mujoco.rollout`, one step from each state), so that no
  Python call is counted;
- a step and its derivatives by forward differences (`mjd_transitionFD`, eps 1e-6, forward: MuJoCo's own
  derivatives of the transition, A = dx'/dx and B = dx'/du), one Python call per state (its call overhead,
  measured on `mj_forward` of a model with nothing in it, is printed too);
- the same by central differences.

Prints one JSON line. `cargo xtask benchmarks --only dynamics` runs it when `python3 -c "import mujoco"`
works (`pip install mujoco`); nothing in the tests needs it.
"""

import json
import math
import sys
import time

import mujoco
import numpy as np
from mujoco import rollout

H = 0.05
X0 = [-math.pi / 4, -math.pi / 6, 0.0]
U = [0.3, -0.2]


def inertial(a, b):
    m = math.pi * a * b
    izz = m * (a * a + b * b) / 4.0
    # The out-of-plane moments never act (every hinge turns about z); any positive values do.
    return f'<inertial pos="{a} 0 0" mass="{m}" diaginertia="{izz} {izz} {izz}"/>'


def finger_xml():
    link = (0.8, 0.25)
    ell = (0.7, 0.5)
    i1 = inertial(*link)
    i2 = inertial(*link)
    m3 = math.pi * ell[0] * ell[1]
    i3 = m3 * (ell[0] ** 2 + ell[1] ** 2) / 4.0
    return f"""
<mujoco model="finger">
  <compiler angle="radian"/>
  <option timestep="{H}" gravity="0 -4 0"/>
  <worldbody>
    <body name="link1" pos="0 0 0">
      <joint name="j1" type="hinge" axis="0 0 1" limited="true" range="{-math.pi} 0" damping="0.2"/>
      {i1}
      <geom name="g1" type="ellipsoid" pos="0.8 0 0" size="0.8 0.25 0.25" contype="0" conaffinity="0"/>
      <body name="link2" pos="1.6 0 0">
        <joint name="j2" type="hinge" axis="0 0 1" limited="true" range="{-2 * math.pi / 3} 0" damping="0.2"/>
        {i2}
        <geom name="g2" type="ellipsoid" pos="0.8 0 0" size="0.8 0.25 0.25" contype="0" conaffinity="0"/>
      </body>
    </body>
    <body name="ellipse" pos="0 -3 0">
      <joint name="j3" type="hinge" axis="0 0 1" damping="0.7"/>
      <inertial pos="0 0 0" mass="{m3}" diaginertia="{i3} {i3} {i3}"/>
      <geom name="g3" type="ellipsoid" size="0.7 0.5 0.5" contype="0" conaffinity="0"/>
    </body>
  </worldbody>
  <contact>
    <pair geom1="g2" geom2="g3" friction="0.5 0.5 0.005 0.0001 0.0001" condim="3"/>
  </contact>
  <actuator>
    <motor joint="j1"/>
    <motor joint="j2"/>
  </actuator>
</mujoco>
"""


def median(values):
    values = sorted(values)
    return values[len(values) // 2]


def main():
    repeats = int(sys.argv[1]) if len(sys.argv) > 1 else 21
    steps = int(sys.argv[2]) if len(sys.argv) > 2 else 75
    model = mujoco.MjModel.from_xml_string(finger_xml())
    data = mujoco.MjData(model)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    nstate = mujoco.mj_stateSize(model, spec)
    data.qpos[:] = X0
    data.ctrl[:] = U
    mujoco.mj_forward(model, data)
    states = []
    for _ in range(steps):
        mujoco.mj_forward(model, data)
        if data.ncon > 0:
            state = np.empty(nstate)
            mujoco.mj_getState(model, data, state, spec)
            states.append(state)
        mujoco.mj_step(model, data)
    if not states:
        print(json.dumps({"error": "the rollout never touched the ellipse"}))
        return
    batch = np.array(states)
    controls = np.tile(np.array(U), (len(states), 1, 1))
    # One step from each state, in C: the median over repeats of the batch's time per state.
    step_times = []
    for _ in range(repeats):
        start = time.perf_counter()
        rollout.rollout(model, data, batch, controls, nstep=1)
        step_times.append((time.perf_counter() - start) / len(states))
    nv, nu = model.nv, model.nu
    a = np.zeros((2 * nv, 2 * nv))
    b = np.zeros((2 * nv, nu))

    def fd_time(centred):
        per_state = []
        for state in states:
            mujoco.mj_setState(model, data, state, spec)
            data.ctrl[:] = U
            times = []
            for _ in range(repeats):
                start = time.perf_counter()
                mujoco.mjd_transitionFD(model, data, 1e-6, centred, a, b, None, None)
                times.append(time.perf_counter() - start)
            per_state.append(min(times))
        return median(per_state)

    forward = fd_time(False)
    central = fd_time(True)
    # Python's share of one such call: mj_forward of an empty model.
    empty = mujoco.MjModel.from_xml_string("<mujoco/>")
    empty_data = mujoco.MjData(empty)
    calls = []
    for _ in range(2001):
        start = time.perf_counter()
        mujoco.mj_forward(empty, empty_data)
        calls.append(time.perf_counter() - start)
    print(json.dumps({
        "version": mujoco.__version__,
        "states": len(states),
        "step_ns": 1e9 * median(step_times),
        "step_fd_forward_ns": 1e9 * forward,
        "step_fd_central_ns": 1e9 * central,
        "python_call_ns": 1e9 * median(calls),
    }))


if __name__ == "__main__":
    main()
