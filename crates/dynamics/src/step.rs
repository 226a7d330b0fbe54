//! One time step `x' = f(x, u)` (paper section III-A, eq. 1; SCENE.md "One time step"): with `M`, `r`, `d`
//! and `J` frozen at the start of the step, solve for the new velocities and the impulses
//!
//! ```text
//! M (v' - v) = h (r + B u) + J^T lambda,   0 <= lambda _|_ d / h + J v' >= 0,   q' = q + h v'
//! ```
//!
//! as a mixed LCP in `z = [v'; lambda]` with the model's NCP function per row (crate `ncp`).

#![allow(non_snake_case)]

use crate::constraint::{Constraints, ContactFrame, ContactImpulse};
use crate::error::DynamicsError;
use crate::kinematics::{Kinematics, Ring};
use crate::scene::Scene;
use ncp::{
    ErmSettings, ErmSolver, Info, LemkeSettings, LinearMcp, NcpFunction, NewtonSettings,
    NewtonSolver, lemke,
};
use serde::{Deserialize, Serialize};

/// How the complementarity rows are modelled.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "snake_case")]
pub enum Complementarity {
    /// The exact LCP, solved by Lemke's method.
    Hard,
    /// Logistic noise on each row's constraint velocity, paper eq. (17), solved by Newton.
    Logistic {
        /// Noise scale (the paper's default 0.1).
        sigma: f64,
    },
    /// Normal noise, expected-residual minimisation, paper eq. (14) with (15).
    Normal {
        /// Noise standard deviation.
        sigma: f64,
    },
}

/// How a step integrates the joints' viscous drag `-c_j v_j`.
///
/// Explicit drag (SCENE.md: "drag, like the rest of r, uses the velocity at the start of the step") is
/// stable only while `h lambda_max(M^-1 D) <= 2`, `D = diag(c)`: a light body on a draggy joint (a thin
/// ellipse, whose inertia falls with its minor axis) breaks that at the finger's h, and each step would
/// then multiply its velocity by `|1 - h c / I| > 1`, creating energy from nothing. The step refuses such a
/// state ([`DynamicsError::UnstableDrag`]) instead. Implicit drag uses the velocity at the end of the step
/// (`M` becomes `M + h D` in the step's equations): it only ever removes energy, at any h.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Drag {
    /// At the start of the step (SCENE.md, the default; refused where it would be unstable).
    #[default]
    Explicit,
    /// At the end of the step: unconditionally dissipative.
    Implicit,
}

/// Settings of a step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StepSettings {
    /// Complementarity model; the paper's default is logistic with sigma = 0.1 (section V-A).
    pub model: Complementarity,
    /// Time step (SCENE.md: 0.05).
    pub h: f64,
    /// How the joints' drag is integrated (SCENE.md: explicitly).
    #[serde(default)]
    pub drag: Drag,
    /// The most penetration one step pushes out: each row's constraint velocity is
    /// `max(d, -recovery) / h + J v'` instead of SCENE.md's `d / h + J v'` (`None`, the default: all of it).
    /// Pushing a penetration of depth `p` out within one step gives the bodies a separating velocity `p / h`,
    /// kinetic energy the step creates; a linearised step can let a thin body deep into another (a needle
    /// turning a radian per step), which then flies off faster than anything hit it. With `Some(0.0)`
    /// penetration is only kept from deepening, never pushed out, and contact only ever removes energy.
    #[serde(default)]
    pub recovery: Option<f64>,
    /// Newton settings for the logistic model.
    pub newton: NewtonSettings,
    /// ERM settings for the normal model.
    pub erm: ErmSettings,
}

impl Default for StepSettings {
    fn default() -> Self {
        StepSettings {
            model: Complementarity::Logistic { sigma: 0.1 },
            h: 0.05,
            drag: Drag::Explicit,
            recovery: None,
            newton: NewtonSettings::default(),
            erm: ErmSettings::default(),
        }
    }
}

impl StepSettings {
    /// `Err` naming the first setting out of range.
    pub fn validate(&self) -> Result<(), DynamicsError> {
        if !(self.h.is_finite() && self.h > 0.0) {
            return Err(DynamicsError::Setting {
                name: "h",
                value: self.h,
                expected: "finite and positive",
            });
        }
        if let Complementarity::Logistic { sigma } | Complementarity::Normal { sigma } = self.model
            && !(sigma.is_finite() && sigma > 0.0)
        {
            return Err(DynamicsError::Setting {
                name: "sigma",
                value: sigma,
                expected: "finite and positive",
            });
        }
        if let Some(depth) = self.recovery
            && !(depth.is_finite() && depth >= 0.0)
        {
            return Err(DynamicsError::Setting {
                name: "recovery",
                value: depth,
                expected: "finite and non-negative (None: no limit)",
            });
        }
        self.newton.validate()?;
        self.erm.validate()?;
        Ok(())
    }
}

/// The outcome of one step.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// `[q + h v'; v']`.
    pub x_next: Vec<f64>,
    /// Row impulses, in the order of [`Scene::rows`](crate::Scene::rows) (SCENE.md's).
    pub lambda: Vec<f64>,
    /// Constraint values `d(q)` at the start of the step.
    pub d: Vec<f64>,
    /// Contact geometry at the start of the step, one per pair.
    pub contacts: Vec<ContactFrame>,
    /// Each contact pair's impulse over the step (from its two rows of `lambda`).
    pub impulses: Vec<ContactImpulse>,
    /// How the complementarity solve went.
    pub info: Info,
}

impl Step {
    /// The step's total normal contact impulse, over every contact pair (joint limits excluded).
    pub fn normal_impulse(&self) -> f64 {
        self.impulses.iter().map(|i| i.normal).sum()
    }
}

/// A simulator: the scene, its settings and the solvers' warm-start state.
#[derive(Debug)]
pub struct Simulator {
    scene: Scene,
    settings: StepSettings,
    newton: NewtonSolver,
    erm: ErmSolver,
    warm: Option<Vec<f64>>,
    covariance: Option<StateCovariance>,
}

/// A Gaussian state estimate's covariance, from which each row's noise follows (paper eq. 18):
/// `Sigma_b = J (Sigma_q / h^2 + Sigma_v) J^T`, row `i` smoothed with `sigma_i = sqrt((Sigma_b)_ii)`.
#[derive(Debug, Clone, PartialEq)]
pub struct StateCovariance {
    /// `Sigma_q`, row-major `n x n` (positions).
    pub q: Vec<f64>,
    /// `Sigma_v`, row-major `n x n` (velocities).
    pub v: Vec<f64>,
}

/// Per-row noise from eq. (18), floored at `1e-12` of the model's constant sigma (a row the covariance does
/// not reach stays smooth rather than hard). Generic so that the derivatives see `sigma_i(q)` through `J(q)`.
pub(crate) fn row_sigmas<T: Ring>(
    cov: &StateCovariance,
    jacobian: &[T],
    n: usize,
    h: f64,
    sigma: f64,
) -> Vec<T> {
    let m = jacobian.len() / n;
    let floor = 1e-12 * sigma;
    (0..m)
        .map(|k| {
            let row = &jacobian[k * n..(k + 1) * n];
            let mut var = T::from(0.0);
            for i in 0..n {
                for j in 0..n {
                    var += row[i] * row[j] * (cov.q[i * n + j] / (h * h) + cov.v[i * n + j]);
                }
            }
            if var.value() > floor * floor {
                var.square_root()
            } else {
                T::from(floor)
            }
        })
        .collect()
}

impl Simulator {
    /// A simulator of `scene` with checked settings.
    pub fn new(scene: Scene, settings: StepSettings) -> Result<Self, DynamicsError> {
        settings.validate()?;
        Ok(Simulator {
            newton: NewtonSolver::new(settings.newton)?,
            erm: ErmSolver::new(settings.erm)?,
            scene,
            settings,
            warm: None,
            covariance: None,
        })
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The settings.
    pub fn settings(&self) -> &StepSettings {
        &self.settings
    }

    /// Smooth each row with the noise a state covariance implies (paper eq. 18) instead of the model's
    /// constant sigma; `None` returns to the constant. Both matrices must be `n x n`, finite, symmetric and
    /// positive semi-definite (checked on the diagonal and by symmetry).
    pub fn set_state_covariance(
        &mut self,
        covariance: Option<StateCovariance>,
    ) -> Result<(), DynamicsError> {
        if let Some(cov) = &covariance {
            let n = self.scene.n_dof();
            for (what, m) in [("covariance q", &cov.q), ("covariance v", &cov.v)] {
                let ok = m.len() == n * n
                    && m.iter().all(|e| e.is_finite())
                    && (0..n).all(|i| m[i * n + i] >= 0.0)
                    && (0..n).all(|i| {
                        (0..n).all(|j| {
                            (m[i * n + j] - m[j * n + i]).abs()
                                <= 1e-12 * (1.0 + m[i * n + j].abs())
                        })
                    });
                if !ok {
                    return Err(DynamicsError::Input {
                        what: "covariance",
                        problem: format!(
                            "{what} must be {n}x{n}, finite, symmetric, with a non-negative diagonal"
                        ),
                    });
                }
            }
        }
        self.covariance = covariance;
        Ok(())
    }

    /// Whether rows take their noise from a state covariance.
    pub fn has_state_covariance(&self) -> bool {
        self.covariance.is_some()
    }

    /// The state covariance rows take their noise from, if any.
    pub fn state_covariance(&self) -> Option<&StateCovariance> {
        self.covariance.as_ref()
    }

    /// Start the next solve from `z = [v'; lambda]` (for instance the solution of an earlier step at the
    /// same state, which the solve then accepts without iterating).
    pub fn set_warm_start(&mut self, z: &[f64]) -> Result<(), DynamicsError> {
        check(
            "warm start",
            z,
            self.scene.n_dof() + self.scene.n_constraints(),
        )?;
        self.warm = Some(z.to_vec());
        Ok(())
    }

    /// Forget the warm start (the next step starts from `[v; 0]`).
    pub fn reset_warm_start(&mut self) {
        self.warm = None;
    }

    /// The mixed LCP of the step from `x` under `u`, with the start-of-step quantities.
    pub fn problem(&self, x: &[f64], u: &[f64]) -> Result<(LinearMcp, Constraints), DynamicsError> {
        self.problem_with(x, u, None)
    }

    /// [`Simulator::problem`] with optional extra generalised forces (checked by the caller).
    fn problem_with(
        &self,
        x: &[f64],
        u: &[f64],
        forces: Option<&[f64]>,
    ) -> Result<(LinearMcp, Constraints), DynamicsError> {
        let scene = &self.scene;
        let n = scene.n_dof();
        check("x", x, scene.n_state())?;
        check("u", u, scene.n_controls)?;
        let (q, v) = x.split_at(n);
        let kin = Kinematics::new(scene, q);
        let mut M = kin.mass_matrix(scene);
        self.check_drag(&M)?;
        self.with_drag(&mut M);
        let mut r = kin.applied_forces(scene, v, u);
        for (r, f) in r.iter_mut().zip(forces.unwrap_or_default()) {
            *r += f;
        }
        let cons = Constraints::new(scene, &kin, q)?;
        self.assemble_problem(v, &M, &r, cons)
    }

    /// A row's distance as the step's constraint velocity sees it: `max(d, -recovery)`
    /// ([`StepSettings::recovery`]).
    pub(crate) fn recovered(&self, d: f64) -> f64 {
        match self.settings.recovery {
            Some(depth) => d.max(-depth),
            None => d,
        }
    }

    /// [`Simulator::recovered`] on distances in a dual type: a clamped row's distance is the constant
    /// `-recovery`, with no derivatives.
    pub(crate) fn recovered_all<T: Ring>(&self, d: &mut [T]) {
        if let Some(depth) = self.settings.recovery {
            for e in d.iter_mut() {
                if e.value() < -depth {
                    *e = T::from(-depth);
                }
            }
        }
    }

    /// The derivative passes' ingredients as the step sees them, in place: explicit drag checked
    /// ([`Simulator::check_drag`]), implicit drag added to `M` ([`Simulator::with_drag`]), the rows'
    /// distances limited by the recovery ([`Simulator::recovered_all`]). Returns the distances as they
    /// were, which the step reports.
    pub(crate) fn prepare_ingredients<T: Ring>(
        &self,
        M: &mut [T],
        d: &mut [T],
    ) -> Result<Vec<f64>, DynamicsError> {
        self.check_drag(M)?;
        self.with_drag(M);
        let distance = d.iter().map(Ring::value).collect();
        self.recovered_all(d);
        Ok(distance)
    }

    /// Implicit drag ([`Drag::Implicit`]): `M + h D` in place of `M` in the step's equations (with `r`
    /// keeping its `-D v`, `(M + h D) v' = M v + h (r + D v) + ...`). Nothing for explicit drag.
    pub(crate) fn with_drag<T: Ring>(&self, M: &mut [T]) {
        if self.settings.drag == Drag::Implicit {
            let n = self.scene.n_dof();
            for (j, b) in self.scene.bodies.iter().enumerate() {
                M[j * n + j] += T::from(self.settings.h * b.damping);
            }
        }
    }

    /// Explicit drag ([`Drag::Explicit`]) is stable while `h lambda_max(M^-1 D) <= 2`; an error naming the
    /// joint that breaks it otherwise. With `M = L L^T` and `W = L^-1 D^1/2`, `lambda_max(M^-1 D)` is that of
    /// `S = W^T W`, at most its trace `|W|_F^2`: that bound settles the usual case in a few flops, and the
    /// eigenvalue itself is computed only when the bound is above `2 / h`.
    pub(crate) fn check_drag<T: Ring>(&self, M: &[T]) -> Result<(), DynamicsError> {
        let h = self.settings.h;
        let scene = &self.scene;
        if self.settings.drag == Drag::Implicit || scene.bodies.iter().all(|b| b.damping == 0.0) {
            return Ok(());
        }
        let n = scene.n_dof();
        // Cholesky in place (lower), then W = L^-1 D^1/2 column by column.
        let mut l: Vec<f64> = M.iter().map(Ring::value).collect();
        for j in 0..n {
            let mut diag = l[j * n + j];
            for k in 0..j {
                diag -= l[j * n + k] * l[j * n + k];
            }
            if diag.is_nan() || diag <= 0.0 {
                return Err(DynamicsError::Unsupported(
                    "the mass matrix is not positive definite at this state",
                ));
            }
            let diag = diag.sqrt();
            l[j * n + j] = diag;
            for i in j + 1..n {
                let mut e = l[i * n + j];
                for k in 0..j {
                    e -= l[i * n + k] * l[j * n + k];
                }
                l[i * n + j] = e / diag;
            }
        }
        let mut w = vec![0.0; n * n];
        for (c, b) in scene.bodies.iter().enumerate() {
            let root = b.damping.sqrt();
            if root == 0.0 {
                continue;
            }
            for i in c..n {
                let mut e = if i == c { root } else { 0.0 };
                for k in c..i {
                    e -= l[i * n + k] * w[k * n + c];
                }
                w[i * n + c] = e / l[i * n + i];
            }
        }
        if h * w.iter().map(|e| e * e).sum::<f64>() <= 2.0 {
            return Ok(());
        }
        let w = nalgebra::DMatrix::from_row_slice(n, n, &w);
        let s = w.transpose() * w;
        let eigen = s.clone().symmetric_eigen();
        let (k, lambda) = eigen.eigenvalues.iter().copied().enumerate().fold(
            (0, f64::NEG_INFINITY),
            |a, (k, l)| if l > a.1 { (k, l) } else { a },
        );
        if h * lambda <= 2.0 {
            return Ok(());
        }
        let mode = eigen.eigenvectors.column(k);
        let joint = (0..n)
            .max_by(|&a, &b| mode[a].abs().total_cmp(&mode[b].abs()))
            .unwrap_or(0);
        Err(DynamicsError::UnstableDrag {
            joint: scene.bodies[joint].name.clone(),
            rate: h * lambda,
            h_max: 2.0 / lambda,
        })
    }

    /// The mixed LCP from its ingredients at the start of the step (`r` holding `B u`).
    pub(crate) fn assemble_problem(
        &self,
        v: &[f64],
        M: &[f64],
        r: &[f64],
        cons: Constraints,
    ) -> Result<(LinearMcp, Constraints), DynamicsError> {
        let n = self.scene.n_dof();
        let m = cons.d.len();
        let h = self.settings.h;
        let dim = n + m;
        let mut a = vec![0.0; dim * dim];
        let mut b = vec![0.0; dim];
        for i in 0..n {
            for j in 0..n {
                a[i * dim + j] = M[i * n + j];
            }
            for k in 0..m {
                a[i * dim + n + k] = -cons.jacobian[k * n + i];
            }
            b[i] = -((0..n).map(|j| M[i * n + j] * v[j]).sum::<f64>() + h * r[i]);
        }
        for k in 0..m {
            for j in 0..n {
                a[(n + k) * dim + j] = cons.jacobian[k * n + j];
            }
            b[n + k] = self.recovered(cons.d[k]) / h;
        }
        Ok((LinearMcp::from_row_major(n, a, b)?, cons))
    }

    /// One step from `x` under the controls `u`.
    #[tracing::instrument(name = "dynamics.step", level = "debug", skip_all)]
    pub fn step(&mut self, x: &[f64], u: &[f64]) -> Result<Step, DynamicsError> {
        let problem = self.problem(x, u)?;
        Ok(self.solve_step(x, problem)?.0)
    }

    /// One step from `x` under the controls `u` with the generalised forces `forces` (one per joint,
    /// held over the step) added to `r + B u`: a user pulling on a body ([`Kinematics::point_force`]).
    pub fn step_with_forces(
        &mut self,
        x: &[f64],
        u: &[f64],
        forces: &[f64],
    ) -> Result<Step, DynamicsError> {
        check("forces", forces, self.scene.n_dof())?;
        let problem = self.problem_with(x, u, Some(forces))?;
        Ok(self.solve_step(x, problem)?.0)
    }

    /// The step from its mixed LCP; also returns the problem (whose matrix the derivatives reuse).
    pub(crate) fn solve_step(
        &mut self,
        x: &[f64],
        (problem, cons): (LinearMcp, Constraints),
    ) -> Result<(Step, LinearMcp), DynamicsError> {
        let n = self.scene.n_dof();
        let m = cons.d.len();
        let mut z = match &self.warm {
            Some(w) if w.len() == n + m => w.clone(),
            _ => {
                let mut z = vec![0.0; n + m];
                z[..n].copy_from_slice(&x[n..]);
                z
            }
        };
        let sigmas = |sigma: f64| -> Vec<f64> {
            match &self.covariance {
                None => vec![sigma; m],
                Some(cov) => row_sigmas(cov, &cons.jacobian, n, self.settings.h, sigma),
            }
        };
        let info = match self.settings.model {
            Complementarity::Hard => {
                let s = lemke(&problem, &LemkeSettings::default())?;
                z = s.z;
                s.info
            }
            Complementarity::Logistic { sigma } => {
                let functions: Vec<NcpFunction> = sigmas(sigma)
                    .into_iter()
                    .map(|sigma| NcpFunction::Logistic { sigma })
                    .collect();
                self.newton.solve_in_place(&problem, &functions, &mut z)?
            }
            Complementarity::Normal { sigma } => {
                let s = self.erm.solve(&problem, &sigmas(sigma), &z)?;
                z = s.z;
                s.info
            }
        };
        let h = self.settings.h;
        let mut x_next = vec![0.0; 2 * n];
        for i in 0..n {
            x_next[i] = x[i] + h * z[i];
            x_next[n + i] = z[i];
        }
        let lambda = z[n..].to_vec();
        self.warm = Some(z);
        let impulses = ContactImpulse::of(&self.scene, &lambda, &cons.contacts);
        let step = Step {
            x_next,
            lambda,
            d: cons.d,
            contacts: cons.contacts,
            impulses,
            info,
        };
        Ok((step, problem))
    }
}

pub(crate) fn check(what: &'static str, v: &[f64], len: usize) -> Result<(), DynamicsError> {
    if v.len() != len {
        return Err(DynamicsError::Input {
            what,
            problem: format!("has {} entries, expected {len}", v.len()),
        });
    }
    if let Some(i) = v.iter().position(|e| !e.is_finite()) {
        return Err(DynamicsError::Input {
            what,
            problem: format!("entry {i} is {}", v[i]),
        });
    }
    Ok(())
}
