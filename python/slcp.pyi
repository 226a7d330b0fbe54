"""Stochastic complementarity for contact: the Rust crates from Python.

A planar contact simulator whose hard contact and friction are smoothed by a stochastic linear
complementarity problem, with exact first and second derivatives; iLQG / DDP on tasks of scene files;
controller libraries and their nearest-neighbour policy (Tassa and Todorov). Arrays are float64 NumPy
arrays; every error of the crates is raised as :class:`SlcpError` with the crate's message.
"""

from os import PathLike
from typing import Any, Optional, Union

import numpy as np
import numpy.typing as npt

__version__: str

ArrayLike = npt.ArrayLike
Path = Union[str, PathLike[str]]
Vector = npt.NDArray[np.float64]
Matrix = npt.NDArray[np.float64]

class SlcpError(ValueError):
    """An error of the crates: a bad scene, task or library file, a bad input (a NaN state, an array of
    the wrong length), an impossible setting."""

class Simulator:
    """One time step of a scene under a contact model, its exact first derivatives and the Hessian of
    ``c . f``. Warm starts carry from one step to the next.

    Arguments: ``scene``, a scene file (TOML, docs/scenes.md) or None for the built-in flicking finger;
    ``model``, ``"logistic"`` (eq. 17), ``"normal"`` (eq. 14 with 15) or ``"hard"`` (the exact LCP);
    ``sigma``, the noise scale of the smoothed models; ``h``, the time step in seconds."""

    def __init__(
        self,
        scene: Optional[Path] = None,
        model: str = "logistic",
        sigma: float = 0.1,
        h: float = 0.05,
    ) -> None:
        """The scene file at ``scene`` (TOML, docs/scenes.md), or the flicking finger of SCENE.md;
        ``model`` is ``"logistic"``, ``"normal"`` (noise scale ``sigma``) or ``"hard"``."""
    def __repr__(self) -> str:
        """``Simulator(scene=None, model='logistic', sigma=0.1, h=0.05) (6 states, 2 controls)``."""
    @property
    def n_state(self) -> int:
        """Length of the state ``x = [q; v]``."""
    @property
    def n_controls(self) -> int:
        """Number of controls."""
    @property
    def state_names(self) -> list[str]:
        """Names of the state's entries (``link1.angle``, ..., ``link1.angle velocity``, ...)."""
    @property
    def h(self) -> float:
        """The time step."""
    def step(self, x: ArrayLike, u: ArrayLike) -> Vector:
        """The next state."""
    def step_info(self, x: ArrayLike, u: ArrayLike) -> dict[str, Any]:
        """The next state ``x_next``, the row impulses ``lambda`` and row distances ``d`` (in the scene's
        row order), each contact pair's ``contact_distance``, ``normal_impulse`` and
        ``tangent_impulse``, and the complementarity solve's ``status``, ``iterations`` and
        ``residual``."""
    def derivatives(self, x: ArrayLike, u: ArrayLike) -> tuple[Vector, Matrix, Matrix]:
        """``(x_next, fx, fu)``: one step and its exact first derivatives, ``fx[i, j] = d x_next[i] /
        d x[j]``, ``fu[i, j] = d x_next[i] / d u[j]``."""
    def hessian(self, x: ArrayLike, u: ArrayLike, c: ArrayLike) -> Matrix:
        """The Hessian of ``c . f(x, u)`` over ``y = (x, u)``, square of side ``n_state +
        n_controls``."""
    def rollout(self, x0: ArrayLike, us: ArrayLike) -> Matrix:
        """The states from ``x0`` under the controls ``us`` (shape ``(N, n_controls)``), shape ``(N + 1,
        n_state)``. Releases the GIL."""
    def reset_warm_start(self) -> None:
        """The next step's solve starts from ``[v; 0]``."""

def optimize(
    scene: Optional[Path] = None,
    task: Optional[str] = None,
    horizon: Optional[int] = None,
    x0: Optional[ArrayLike] = None,
    us: Optional[ArrayLike] = None,
    iterations: Optional[int] = None,
    method: str = "full",
    model: Optional[str] = None,
    sigma: Optional[float] = None,
    h: Optional[float] = None,
    threads: int = 1,
    max_iterations: Optional[int] = None,
    continuation: bool = True,
) -> dict[str, Any]:
    """iLQG / DDP on a task of a scene file (its only task when ``task`` is None; the finger's
    ``spin`` without a scene), full second-order DDP (``method="full"``) or Gauss-Newton iLQR
    (``"ilqr"``), from zero controls or ``us``, at most ``iterations`` passes (300 when neither it nor
    its alias ``max_iterations`` is given), each pass's knots differentiated on ``threads`` threads.
    Where the solve never touches the contact its task needs, it reaches for it as ``cargo xtask
    optimize`` does (pulls, then continuation in the noise scale), unless ``continuation`` is False.
    Returns ``states`` (N+1, n), ``controls`` (N, m), ``gains`` (N, m, n) with ``u = controls[i] +
    gains[i] @ (x - states[i])``, the local value model ``cost_to_go`` (N+1,), ``value_gradient`` (N+1,
    n) and ``value_hessian`` (N+1, n, n), ``cost``, ``passes``, ``status`` (``"cost converged"``,
    ``"step converged"``, ``"pass limit reached"``, ``"no descent"``, ``"regularisation exceeded"``, or
    ``"no contact felt"``), ``optimiser_status`` (the optimiser's alone), ``converged`` (converged with
    the contact felt), ``contact`` (``"felt"``, ``"pulled A-B together"``, ``"continued in the noise
    scale"`` or ``"not felt: ..."``; ``"; explored from random starts"`` appended where a progress
    task's solve stalled and a solve from smooth random starts replaced it) and ``task``. Releases the
    GIL."""

class Library:
    """A controller library (paper section IV-C) and its global nearest-neighbour policy."""

    @staticmethod
    def train(
        scene: Optional[Path] = None,
        task: Optional[str] = None,
        trajectories: int = 400,
        seed: int = 1,
        paper: bool = False,
        horizon: Optional[int] = None,
        growth: Optional[int] = None,
        trunk: Optional[int] = None,
        settle: Optional[int] = None,
        length: Optional[int] = None,
        chains: int = 1,
        model: Optional[str] = None,
        sigma: Optional[float] = None,
        threads: int = 1,
    ) -> "Library":
        """Build a library as ``cargo xtask train`` does: for a task of a scene file (its only one when
        ``task`` is None; without a scene the built-in ``scenes/finger.toml``, whose only task is the
        paper's ``spin``); the default recipe or the paper's (``paper=True``); the
        task's contact model and sigma unless ``model`` or ``sigma`` is given. Releases the GIL."""
    @staticmethod
    def load(path: Path) -> "Library":
        """A library file written by :meth:`save` or ``cargo xtask train``."""
    def save(self, path: Path) -> None:
        """Write the library file."""
    def __len__(self) -> int:
        """Number of local controllers."""
    def __repr__(self) -> str:
        """``<slcp.Library: 32 controllers for task 'spin', logistic contact, sigma 0.1, h = 0.05>``."""
    @property
    def states(self) -> Matrix:
        """The controllers' states, shape ``(len, n_state)``."""
    @property
    def task(self) -> str:
        """The name of the task it was built for (``spin`` for the built-in finger's)."""
    @property
    def settings(self) -> dict[str, Any]:
        """The settings it was built with."""
    @property
    def x0(self) -> Vector:
        """The initial state of its first trajectory."""
    def policy(self, x: ArrayLike) -> Vector:
        """The global policy's control at ``x``."""
    def evaluate(
        self,
        seconds: float = 200.0,
        model: Optional[str] = None,
        sigma: Optional[float] = None,
        h: Optional[float] = None,
        kick_every: float = 10.0,
        kick_std: float = 2.0,
        seed: int = 7,
        x0: Optional[ArrayLike] = None,
    ) -> dict[str, Any]:
        """The policy in closed loop (``cargo xtask evaluate``'s measures, with the task's own under
        ``"task"``) on the library's own model, or ``model`` (``"logistic"``, ``"normal"``, ``"hard"``),
        with ``sigma`` replacing the noise scale (refused for the hard model), at the library's time step
        or ``h``, from its initial state or ``x0``. Releases the GIL."""
