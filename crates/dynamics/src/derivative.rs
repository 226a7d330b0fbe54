//! Exact first derivatives of the step, `fx = dx'/dx` and `fu = dx'/du`, by the implicit function theorem
//! on the step's equations (paper section IV: the smoothed impulses are differentiable functions of the
//! state).
//!
//! At the solution `z = [v'; lambda]` of `Phi(z; x, u) = 0`, with
//! `Phi = [M (v' - v) - h (r + B u) - J^T lambda; phi_i(lambda_i, w_i)]` and `w = d / h + J v'`,
//! `dz = -Phi_z^-1 Phi_x dx`. `Phi_z` is the Newton matrix of the solve; `Phi_x` comes from the same
//! kinematics code run in forward-mode dual numbers, through `geometry::signed_distance_dual` for the
//! contact rows, eight directions per pass: all of the finger's state and control entries at
//! once), then `q' = q + h v'` gives `fx = [[I + h dv'/dq, h dv'/dv]; [dv'/dq, dv'/dv]]` and `fu = [h dv'/du; dv'/du]`.
//!
//! For the hard model the derivative is that of the active set: rows with `lambda_i > 0` are held as
//! equalities `w_i = 0`, the others dropped (`lambda_i = 0`); it is the derivative of the step wherever the
//! active set does not change, and one-sided where it does.

#![allow(non_snake_case)]

use crate::constraint::{Constraints, ContactFrame};
use crate::error::DynamicsError;
use crate::jet::{Jet, Jet1};
use crate::kinematics::{Kinematics, Ring, Scalar};
use crate::scene::Scene;
use crate::step::{Complementarity, Simulator, Step, check, row_sigmas};
use nalgebra::{SMatrix, SVector};
use ncp::{
    DenseLu, LinearSolver, Mcp, NcpFunction, normal_expected_squared, normal_expected_squared_third,
};
use num_dual::{Derivative, Dual2SVec64, DualSVec64};

/// `fx` (row-major `2n x 2n`, `fx[i][j] = dx'_i / dx_j`) and `fu` (row-major `2n x n_u`).
#[derive(Debug, Clone, PartialEq)]
pub struct StepDerivatives {
    /// `dx'/dx`, row-major.
    pub fx: Vec<f64>,
    /// `dx'/du`, row-major.
    pub fu: Vec<f64>,
}

/// The step's equations at `(x, u)` for a given `z = [v'; lambda]`: the equation-of-motion residual
/// `M (v' - v) - h (r + B u) - J^T lambda` and the constraint velocities `w = d / h + J v'` (explicit drag,
/// SCENE.md's).
pub fn step_residual<T: Scalar>(
    scene: &Scene,
    h: f64,
    x: &[T],
    u: &[T],
    z: &[f64],
) -> Result<(Vec<T>, Vec<T>), DynamicsError> {
    let z: Vec<T> = z.iter().map(|&e| T::from(e)).collect();
    step_residual_at(scene, h, x, u, &z)
}

/// As [`step_residual`], with `z` in the dual type too.
pub fn step_residual_at<T: Scalar>(
    scene: &Scene,
    h: f64,
    x: &[T],
    u: &[T],
    z: &[T],
) -> Result<(Vec<T>, Vec<T>), DynamicsError> {
    let n = scene.n_dof();
    let (q, v) = x.split_at(n);
    let kin = Kinematics::new(scene, q);
    let M = kin.mass_matrix(scene);
    let r = kin.applied_forces(scene, v, u);
    let cons = Constraints::new(scene, &kin, q)?;
    Ok(assemble(n, h, &M, &r, &cons.jacobian, &cons.d, v, z))
}

/// The step's equations from their ingredients: `M (v' - v) - h r - J^T lambda` and `d / h + J v'`
/// (`r` already holds `B u`).
#[allow(clippy::too_many_arguments)]
fn assemble<T: Scalar>(
    n: usize,
    h: f64,
    M: &[T],
    r: &[T],
    jac: &[T],
    d: &[T],
    v: &[T],
    z: &[T],
) -> (Vec<T>, Vec<T>) {
    let m = d.len();
    let (v_next, lambda) = z.split_at(n);
    let mut free = Vec::with_capacity(n);
    for i in 0..n {
        let mut s = -r[i] * h;
        for j in 0..n {
            s += M[i * n + j] * (-v[j] + v_next[j]);
        }
        for k in 0..m {
            s -= jac[k * n + i] * lambda[k];
        }
        free.push(s);
    }
    let w = (0..m)
        .map(|k| {
            let mut s = d[k] / h;
            for j in 0..n {
                s += jac[k * n + j] * v_next[j];
            }
            s
        })
        .collect();
    (free, w)
}

/// Directions of a vector-dual pass over `y = (x, u)`: the finger's 6 state and 2 control entries at once.
const DIRECTIONS: usize = 8;

type D1 = DualSVec64<DIRECTIONS>;
type D2 = Dual2SVec64<DIRECTIONS>;
/// The first derivatives' ingredients, all of one chunk of `y` at once.
type F1 = Jet1<DIRECTIONS>;
/// The geometry and kinematics over the joint angles (three joints at most).
type Q2 = Jet<3>;
/// The forces over `(q, v)` (three joints at most).
type R2 = Jet<6>;

/// The step's ingredients at `(x, u)` in some scalar type: `M`, `r + B u`, `J`, `d` and each row's noise.
struct Ingredients<T> {
    contacts: Vec<ContactFrame>,
    /// Each row's distance `d(q)` (the step reports it; `d` below is what the rows see,
    /// [`crate::StepSettings::recovery`]).
    distance: Vec<f64>,
    M: Vec<T>,
    r: Vec<T>,
    jac: Vec<T>,
    d: Vec<T>,
    sigma: Vec<T>,
}

/// The second-order ingredients before lifting: functions of `q` (three directions) and the forces, a
/// function of `(q, v)` (six); `r` holds `B u` in value only (it is linear in `u`).
struct SecondOrder {
    n: usize,
    contacts: Vec<ContactFrame>,
    distance: Vec<f64>,
    /// `(joint, direction of its control in y)`.
    actuated: Vec<(usize, usize)>,
    M: Vec<Q2>,
    jac: Vec<Q2>,
    d: Vec<Q2>,
    sigma: Vec<Q2>,
    r: Vec<R2>,
}

impl SecondOrder {
    /// The ingredients as numbers over all of `y`, from the jets' conversions `q` and `r` and the
    /// controls' directions `unit(k)` (the forces' `B u`, linear in `u`).
    fn convert<T: Scalar>(
        &self,
        q: impl Fn(&Q2) -> T,
        r: impl Fn(&R2) -> T,
        unit: impl Fn(usize) -> T,
    ) -> Ingredients<T> {
        let map = |v: &[Q2]| v.iter().map(&q).collect::<Vec<_>>();
        let mut forces: Vec<T> = self.r.iter().map(r).collect();
        for &(j, k) in &self.actuated {
            forces[j] += unit(k);
        }
        Ingredients {
            contacts: self.contacts.clone(),
            distance: self.distance.clone(),
            M: map(&self.M),
            r: forces,
            jac: map(&self.jac),
            d: map(&self.d),
            sigma: map(&self.sigma),
        }
    }

    /// The first-order ingredients over all of `y`.
    fn first_order(&self) -> Ingredients<D1> {
        self.convert(jet_first, jet_first, |k| D1::from_re(0.0).derivative(k))
    }

    /// All of it lifted to second-order duals over `y`.
    fn lifted(&self) -> Ingredients<D2> {
        self.convert(jet_second, jet_second, |k| D2::from_re(0.0).derivative(k))
    }

    /// The Hessians in `s` of the logistic and hard models' equations `K_i(p0 + dp s, y0 + s)` with a
    /// constant sigma, row-major `cols x cols` each, assembled in plain arrays from the structure of
    /// [`system`] instead of in eight-direction duals: every product there is of a function of `q` alone
    /// (gradient and Hessian over the first `n` directions, from the three-direction duals) and a function
    /// affine in `s`, and each row is a function of two such quantities (`lambda_i`, `w_i`).
    #[allow(clippy::too_many_arguments)]
    fn equation_hessians(
        &self,
        h: f64,
        x: &[f64],
        p: &[f64],
        dp: &[f64],
        cols: usize,
        kinds: &[RowKind],
        sigma: f64,
    ) -> Vec<f64> {
        let n = self.n;
        let m = self.d.len();
        let cc = cols * cols;
        let grad = |d: &Q2| -> [f64; 3] { d.g };
        // out += scale * H_q(f) in the leading n x n block.
        let add_q = |out: &mut [f64], f: &Q2, scale: f64| {
            for i in 0..n {
                for j in 0..n {
                    out[i * cols + j] += scale * f.h[i][j];
                }
            }
        };
        // out += scale * (a b^T + b a^T), a over the first n directions.
        let add_sym = |out: &mut [f64], a: &[f64; 3], b: &[f64], scale: f64| {
            for i in 0..n {
                let ai = scale * a[i];
                if ai == 0.0 {
                    continue;
                }
                for j in 0..cols {
                    out[i * cols + j] += ai * b[j];
                    out[j * cols + i] += ai * b[j];
                }
            }
        };
        let row = |i: usize| &dp[i * cols..(i + 1) * cols];
        let mut out = vec![0.0; (n + m) * cc];
        let mut dl = [0.0; DIRECTIONS];
        let mut hw = vec![0.0; cc];
        let mut gw = [0.0; DIRECTIONS];
        // Equations of motion: sum_j M_ij (v'_j - v_j) - h r_i - sum_k J_ki lambda_k.
        for i in 0..n {
            let e = &mut out[i * cc..(i + 1) * cc];
            for j in 0..n {
                let f = &self.M[i * n + j];
                dl[..cols].copy_from_slice(row(j));
                dl[n + j] -= 1.0;
                add_q(e, f, p[j] - x[n + j]);
                add_sym(e, &grad(f), &dl[..cols], 1.0);
            }
            for k in 0..m {
                let f = &self.jac[k * n + i];
                add_q(e, f, -p[n + k]);
                add_sym(e, &grad(f), row(n + k), -1.0);
            }
            let hm = &self.r[i].h;
            for a in 0..2 * n {
                for b in 0..2 * n {
                    e[a * cols + b] -= h * hm[a][b];
                }
            }
        }
        // Rows: w_k = d_k / h + sum_j J_kj v'_j, then lambda_k, w_k or phi(lambda_k, w_k).
        for k in 0..m {
            if kinds[k] == RowKind::Fixed {
                continue;
            }
            hw.iter_mut().for_each(|e| *e = 0.0);
            gw.iter_mut().for_each(|e| *e = 0.0);
            let gd = grad(&self.d[k]);
            add_q(&mut hw, &self.d[k], 1.0 / h);
            for i in 0..n {
                gw[i] += gd[i] / h;
            }
            for j in 0..n {
                let f = &self.jac[k * n + j];
                let gf = grad(f);
                add_q(&mut hw, f, p[j]);
                add_sym(&mut hw, &gf, row(j), 1.0);
                for i in 0..n {
                    gw[i] += p[j] * gf[i];
                }
                for (g, d) in gw.iter_mut().zip(row(j)) {
                    *g += f.re * d;
                }
            }
            let e = &mut out[(n + k) * cc..(n + k + 1) * cc];
            match kinds[k] {
                RowKind::Contact => e.copy_from_slice(&hw),
                RowKind::Logistic => {
                    let w0 = self.d[k].re / h
                        + (0..n).map(|j| self.jac[k * n + j].re * p[j]).sum::<f64>();
                    let jet = NcpFunction::Logistic { sigma }.jet(p[n + k], w0);
                    let gl = row(n + k);
                    for a in 0..cols {
                        for b in 0..cols {
                            e[a * cols + b] = jet.db * hw[a * cols + b]
                                + jet.daa * gl[a] * gl[b]
                                + jet.dab * (gl[a] * gw[b] + gw[a] * gl[b])
                                + jet.dbb * gw[a] * gw[b];
                        }
                    }
                }
                _ => unreachable!("logistic and hard rows are fixed, contact or logistic"),
            }
        }
        out
    }
}

/// The first-order part of a jet over the leading entries of `y`.
fn jet_first<const N: usize>(d: &Jet<N>) -> D1 {
    let mut grad = SVector::<f64, DIRECTIONS>::zeros();
    for i in 0..N {
        grad[i] = d.g[i];
    }
    D1::new(d.re, Derivative::some(grad))
}

/// A first-order jet over `y` (or a chunk of it) as the vector dual of the step's equations.
fn jet1_dual(d: &F1) -> D1 {
    D1::new(d.re, Derivative::some(SVector::from(d.g)))
}

/// A jet over the leading entries of `y` as a second-order dual over all of `y`.
fn jet_second<const N: usize>(d: &Jet<N>) -> D2 {
    let mut grad = SMatrix::<f64, 1, DIRECTIONS>::zeros();
    let mut hess = SMatrix::<f64, DIRECTIONS, DIRECTIONS>::zeros();
    for i in 0..N {
        grad[(0, i)] = d.g[i];
        for j in 0..N {
            hess[(i, j)] = d.h[i][j];
        }
    }
    D2::new(d.re, Derivative::some(grad), Derivative::some(hess))
}

/// The unknowns at the solution, the Jacobian of the equations in them (and its factors), each row's kind.
type Equations = (Vec<f64>, Vec<f64>, DenseLu, Vec<RowKind>);

/// What a complementarity row of the linearised step is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum RowKind {
    /// `lambda_i` held at its value: an inactive hard row, a normal row on its bound, or a redundant row.
    Fixed,
    /// An active hard row, `w_i = 0`.
    Contact,
    /// The logistic function of eq. (17), `phi(lambda_i, w_i; sigma_i) = 0`.
    Logistic,
    /// A normal (ERM) row off its bound: the stationarity `d E_i / d lambda_i - (J nu)_i = 0`.
    Stationary,
}

/// The equations whose root the step is, in the unknowns `p`:
///
/// - logistic and hard: `p = [v'; lambda]`, `[M (v' - v) - h r - J^T lambda; row_i(lambda_i, w_i)]`;
/// - normal (eq. 14 with 15 as an optimisation over `lambda >= 0` with `v'` from the equations of motion):
///   `p = [v'; lambda; nu]` and the first-order conditions
///   `[M (v' - v) - h r - J^T lambda; J^T e_b + M nu; e_a,i - (J nu)_i or lambda_i]`, `e = E[min(lambda, w +
///   sigma xi)^2]` per row, its derivatives in `(lambda, w)` carried to second order by their Taylor
///   polynomials around the solution (exact for first and second derivatives of the step).
fn system<T: Scalar>(
    n: usize,
    h: f64,
    ing: &Ingredients<T>,
    v: &[T],
    p: &[T],
    kinds: &[RowKind],
    normal: bool,
) -> Vec<T> {
    let m = ing.d.len();
    let (vn, rest) = p.split_at(n);
    let lambda = &rest[..m];
    let mut out = Vec::with_capacity(p.len());
    for i in 0..n {
        let mut s = -ing.r[i] * h;
        for j in 0..n {
            s += ing.M[i * n + j] * (vn[j] - v[j]);
        }
        for k in 0..m {
            s -= ing.jac[k * n + i] * lambda[k];
        }
        out.push(s);
    }
    let w: Vec<T> = (0..m)
        .map(|k| {
            let mut s = ing.d[k] / h;
            for j in 0..n {
                s += ing.jac[k * n + j] * vn[j];
            }
            s
        })
        .collect();
    if !normal {
        for k in 0..m {
            out.push(match kinds[k] {
                RowKind::Fixed => lambda[k],
                RowKind::Contact => w[k],
                RowKind::Logistic => logistic(lambda[k], w[k], ing.sigma[k]),
                RowKind::Stationary => unreachable!("stationary rows belong to the normal model"),
            });
        }
        return out;
    }
    let nu = &rest[m..m + n];
    let mut ea = Vec::with_capacity(m);
    let mut eb = Vec::with_capacity(m);
    for k in 0..m {
        let (l0, w0, sigma) = (lambda[k].re(), w[k].re(), ing.sigma[k].re());
        let j = normal_expected_squared(l0, w0, sigma);
        let [aaa, aab, abb, bbb] = normal_expected_squared_third(l0, w0, sigma);
        let (dl, dw) = (lambda[k] - l0, w[k] - w0);
        let (ll, lw, ww) = (dl * dl * 0.5, dl * dw, dw * dw * 0.5);
        ea.push(dl * j.daa + dw * j.dab + ll * aaa + lw * aab + ww * abb + j.da);
        eb.push(dl * j.dab + dw * j.dbb + ll * aab + lw * abb + ww * bbb + j.db);
    }
    for i in 0..n {
        let mut s = T::from(0.0);
        for k in 0..m {
            s += ing.jac[k * n + i] * eb[k];
        }
        for j in 0..n {
            s += ing.M[i * n + j] * nu[j];
        }
        out.push(s);
    }
    for k in 0..m {
        out.push(match kinds[k] {
            RowKind::Fixed => lambda[k],
            RowKind::Stationary => {
                let mut s = ea[k];
                for j in 0..n {
                    s -= ing.jac[k * n + j] * nu[j];
                }
                s
            }
            _ => unreachable!("normal rows are fixed or stationary"),
        });
    }
    out
}

impl Simulator {
    /// Each row's noise in the scalar type of `jac`: the model's constant, or eq. (18) through `J(q)`.
    fn noise<T: Ring>(&self, jac: &[T], m: usize) -> Vec<T> {
        let sigma = match self.settings().model {
            Complementarity::Hard => 0.0,
            Complementarity::Logistic { sigma } | Complementarity::Normal { sigma } => sigma,
        };
        match self.state_covariance() {
            Some(cov) => row_sigmas(cov, jac, self.scene().n_dof(), self.settings().h, sigma),
            None => vec![T::from(sigma); m],
        }
    }

    /// The ingredients in first-order duals over `y[first..first + 8]`. With three joints or fewer the
    /// geometry (the expensive part) runs in three directions only and is lifted.
    fn first_order_ingredients(
        &self,
        x: &[f64],
        u: &[f64],
        first: usize,
    ) -> Result<Ingredients<D1>, DynamicsError> {
        let scene = self.scene();
        let n = scene.n_dof();
        let ys: Vec<F1> = x
            .iter()
            .chain(u)
            .enumerate()
            .map(|(j, &e)| {
                if (first..first + DIRECTIONS).contains(&j) {
                    F1::variable(e, j - first)
                } else {
                    F1::from(e)
                }
            })
            .collect();
        let (xs, us) = ys.split_at(2 * n);
        let kin = Kinematics::new(scene, &xs[..n]);
        let r = kin.applied_forces(scene, &xs[n..], us);
        let cons = Constraints::new(scene, &kin, &xs[..n])?;
        let sigma = self.noise(&cons.jacobian, cons.d.len());
        let dual = |v: &[F1]| v.iter().map(jet1_dual).collect::<Vec<_>>();
        let mut M = kin.mass_matrix(scene);
        let mut d = cons.d;
        let distance = self.prepare_ingredients(&mut M, &mut d)?;
        Ok(Ingredients {
            contacts: cons.contacts,
            distance,
            M: dual(&M),
            r: dual(&r),
            jac: dual(&cons.jacobian),
            d: dual(&d),
            sigma: dual(&sigma),
        })
    }

    /// The ingredients in second-order duals (three joints or fewer, `2n + n_u <= 8`): the geometry over the
    /// joint angles, the forces over `(q, v)`, to be lifted to all of `y`.
    fn second_order_ingredients(&self, x: &[f64], u: &[f64]) -> Result<SecondOrder, DynamicsError> {
        let scene = self.scene();
        let n = scene.n_dof();
        let q: Vec<Q2> = (0..n).map(|i| Q2::variable(x[i], i)).collect();
        let kin3 = Kinematics::new(scene, &q);
        let cons = Constraints::new(scene, &kin3, &q)?;
        let qv: Vec<R2> = (0..2 * n).map(|i| R2::variable(x[i], i)).collect();
        let u6: Vec<R2> = u.iter().map(|&e| R2::from(e)).collect();
        let r = Kinematics::new(scene, &qv[..n]).applied_forces(scene, &qv[n..], &u6);
        let sigma = self.noise(&cons.jacobian, cons.d.len());
        let mut M = kin3.mass_matrix(scene);
        let mut d = cons.d;
        let distance = self.prepare_ingredients(&mut M, &mut d)?;
        Ok(SecondOrder {
            n,
            contacts: cons.contacts.clone(),
            distance,
            actuated: scene
                .bodies
                .iter()
                .enumerate()
                .filter_map(|(j, b)| b.actuator.map(|k| (j, 2 * n + k)))
                .collect(),
            M,
            jac: cons.jacobian,
            d,
            sigma,
            r,
        })
    }

    /// The step, the Jacobian of its equations in their unknowns and `dp/d(x, u)`.
    /// With `second` (the Hessian pass computes them anyway) the first-order ingredients are read off it.
    fn linearise(
        &mut self,
        x: &[f64],
        u: &[f64],
        second: Option<&SecondOrder>,
        given: Option<&Step>,
    ) -> Result<Linearised, DynamicsError> {
        let model = self.settings().model;
        if self.has_state_covariance() && matches!(model, Complementarity::Normal { .. }) {
            return Err(DynamicsError::Unsupported(
                "derivatives of the normal model with per-row noise from a state covariance",
            ));
        }
        let (n, nu) = (self.scene().n_dof(), self.scene().n_controls);
        check("x", x, 2 * n)?;
        check("u", u, nu)?;
        // The ingredients in duals first: their values make the step's problem (the geometry runs once).
        let cols = 2 * n + nu;
        let mut passes = Vec::with_capacity(cols.div_ceil(DIRECTIONS));
        for first in (0..cols).step_by(DIRECTIONS) {
            passes.push(match second {
                Some(so) if first == 0 => so.first_order(),
                _ => self.first_order_ingredients(x, u, first)?,
            });
        }
        let values = |v: &[D1]| v.iter().map(|e| e.re).collect::<Vec<f64>>();
        let ing = &passes[0];
        let cons = Constraints {
            d: ing.distance.clone(),
            jacobian: values(&ing.jac),
            contacts: ing.contacts.clone(),
        };
        let (step, problem) = match given {
            // The step computed before at (x, u): linearise its solution, no second solve.
            Some(step) => {
                let m = cons.d.len();
                if step.x_next.len() != 2 * n || step.lambda.len() != m {
                    return Err(DynamicsError::Input {
                        what: "step",
                        problem: format!(
                            "has {} state entries and {} impulses; a step from this x has {} and {m}",
                            step.x_next.len(),
                            step.lambda.len(),
                            2 * n
                        ),
                    });
                }
                let (problem, _) =
                    self.assemble_problem(&x[n..], &values(&ing.M), &values(&ing.r), cons)?;
                (step.clone(), problem)
            }
            None => {
                let problem =
                    self.assemble_problem(&x[n..], &values(&ing.M), &values(&ing.r), cons)?;
                self.solve_step(x, problem)?
            }
        };
        if step.info.status != ncp::Status::Converged {
            return Err(DynamicsError::Unsupported(
                "derivatives of a step whose complementarity solve did not converge",
            ));
        }
        let m = step.lambda.len();
        let h = self.settings().h;
        let mut z = step.x_next[n..].to_vec();
        z.extend_from_slice(&step.lambda);
        let dim = n + m;
        let mut f = vec![0.0; dim];
        let mut jac = vec![0.0; dim * dim];
        problem.evaluate(&z, &mut f, Some(&mut jac));
        let normal = matches!(model, Complementarity::Normal { .. });
        let (p, _, mut lu, kinds) = if normal {
            self.normal_system(&z, &f, &jac, n)?
        } else {
            self.complementarity_system(&z, &f, &jac, n)?
        };
        let np = p.len();
        // The equations' derivatives in y = (x, u), eight directions per pass (one pass for the finger).
        let pc: Vec<D1> = p.iter().map(|&e| D1::from_re(e)).collect();
        let mut dp = vec![0.0; np * cols];
        for (ing, first) in passes.iter().zip((0..cols).step_by(DIRECTIONS)) {
            let v: Vec<D1> = (0..n)
                .map(|j| {
                    let d = D1::from_re(x[n + j]);
                    if (first..first + DIRECTIONS).contains(&(n + j)) {
                        d.derivative(n + j - first)
                    } else {
                        d
                    }
                })
                .collect();
            let res = system(n, h, ing, &v, &pc, &kinds, normal);
            for k in 0..DIRECTIONS.min(cols - first) {
                for (i, e) in res.iter().enumerate() {
                    dp[i * cols + first + k] = -e.eps.0.as_ref().map_or(0.0, |g| g[k]);
                }
            }
        }
        lu.solve_many(&mut dp, cols);
        Ok(Linearised {
            step,
            p,
            lu,
            dp,
            kinds,
        })
    }

    /// Logistic and hard models: `p = z`, the Newton matrix with each row's `(d phi/d lambda, d phi/d w)`;
    /// redundant active rows held fixed.
    fn complementarity_system(
        &self,
        z: &[f64],
        f: &[f64],
        jac: &[f64],
        n: usize,
    ) -> Result<Equations, DynamicsError> {
        let dim = z.len();
        let m = dim - n;
        let model = self.settings().model;
        let sigmas: Vec<f64> = match self.state_covariance() {
            Some(_) => {
                let rows: Vec<f64> = (0..m)
                    .flat_map(|k| jac[(n + k) * dim..(n + k) * dim + n].to_vec())
                    .collect();
                self.noise(&rows, m)
            }
            None => self.noise(&vec![0.0; m * n], m),
        };
        let mut kinds = Vec::with_capacity(m);
        let mut dphi = vec![(0.0, 0.0); m];
        for k in 0..m {
            let (lambda, w) = (z[n + k], f[n + k]);
            let (kind, d) = match model {
                Complementarity::Logistic { .. } => {
                    let sigma = sigmas[k];
                    let (_, da, db) = NcpFunction::Logistic { sigma }.first_order(lambda, w);
                    (RowKind::Logistic, (da, db))
                }
                _ if lambda > 0.0 => (RowKind::Contact, (0.0, 1.0)),
                _ => (RowKind::Fixed, (1.0, 0.0)),
            };
            kinds.push(kind);
            dphi[k] = d;
        }
        let build = |dphi: &[(f64, f64)]| {
            let mut H = jac.to_vec();
            for k in 0..m {
                let row = &mut H[(n + k) * dim..(n + k + 1) * dim];
                for e in row.iter_mut() {
                    *e *= dphi[k].1;
                }
                row[n + k] += dphi[k].0;
            }
            H
        };
        let mut H = build(&dphi);
        let mut lu = DenseLu::new(dim, LinearSolver::Hand);
        // Redundant active rows (more than the velocities can satisfy independently) make the matrix
        // singular: exactly for the hard model's active set, to working precision for a smoothed row whose
        // d phi / d lambda has underflowed (lambda >> sigma). The velocities are still unique. Hold the
        // smallest impulses of such rows fixed, one at a time, until the remaining active rows are
        // independent: the derivative of that branch of impulses, and the derivative of v'.
        while !lu.factor(&H) {
            let weakest = (0..m)
                .filter(|&k| dphi[k].1 > 0.5 && dphi[k].0 < 1e-12)
                .min_by(|&a, &b| z[n + a].total_cmp(&z[n + b]));
            match weakest {
                Some(k) => {
                    dphi[k] = (1.0, 0.0);
                    kinds[k] = RowKind::Fixed;
                    H = build(&dphi);
                }
                None => {
                    return Err(DynamicsError::Unsupported(
                        "the step's Jacobian is singular at this state",
                    ));
                }
            }
        }
        Ok((z.to_vec(), H, lu, kinds))
    }

    /// Normal model: `p = [v'; lambda; nu]` with `nu = -M^-1 J^T e_b` and the first-order conditions'
    /// Jacobian; rows with `lambda_i = 0` are on their bound and held there.
    fn normal_system(
        &self,
        z: &[f64],
        f: &[f64],
        jac: &[f64],
        n: usize,
    ) -> Result<Equations, DynamicsError> {
        let dim = z.len();
        let m = dim - n;
        let sigmas = self.noise(&vec![0.0; m * n], m);
        let M = |i: usize, j: usize| jac[i * dim + j];
        let J = |k: usize, j: usize| jac[(n + k) * dim + j];
        let jets: Vec<_> = (0..m)
            .map(|k| normal_expected_squared(z[n + k], f[n + k], sigmas[k]))
            .collect();
        let kinds: Vec<RowKind> = (0..m)
            .map(|k| {
                if z[n + k] > 0.0 {
                    RowKind::Stationary
                } else {
                    RowKind::Fixed
                }
            })
            .collect();
        // nu from M nu = -J^T e_b.
        let mut lu = DenseLu::new(n, LinearSolver::Hand);
        let mass: Vec<f64> = (0..n * n).map(|e| M(e / n, e % n)).collect();
        if !lu.factor(&mass) {
            return Err(DynamicsError::Unsupported("a singular mass matrix"));
        }
        let mut nu: Vec<f64> = (0..n)
            .map(|i| -(0..m).map(|k| J(k, i) * jets[k].db).sum::<f64>())
            .collect();
        lu.solve(&mut nu);
        let np = 2 * n + m;
        let mut H = vec![0.0; np * np];
        for i in 0..n {
            for j in 0..n {
                H[i * np + j] = M(i, j);
                // K2 = J^T e_b + M nu: d/dv' = J^T diag(e_bb) J, d/dlambda = J^T diag(e_ab), d/dnu = M.
                H[(n + i) * np + n + m + j] = M(i, j);
                H[(n + i) * np + j] = (0..m).map(|k| J(k, i) * jets[k].dbb * J(k, j)).sum();
            }
            for k in 0..m {
                H[i * np + n + k] = -J(k, i);
                H[(n + i) * np + n + k] = J(k, i) * jets[k].dab;
            }
        }
        for k in 0..m {
            let row = n + n + k;
            match kinds[k] {
                RowKind::Stationary => {
                    for j in 0..n {
                        H[row * np + j] = jets[k].dab * J(k, j);
                        H[row * np + n + m + j] = -J(k, j);
                    }
                    H[row * np + n + k] = jets[k].daa;
                }
                _ => H[row * np + n + k] = 1.0,
            }
        }
        let mut p = z.to_vec();
        p.extend_from_slice(&nu);
        let mut lu = DenseLu::new(np, LinearSolver::Hand);
        if !lu.factor(&H) {
            return Err(DynamicsError::Unsupported(
                "the step's Jacobian is singular at this state",
            ));
        }
        Ok((p, H, lu, kinds))
    }

    /// One step and its exact derivatives, for every model: the hard model's are its active set's (module
    /// documentation), the normal model's those of the first-order conditions of its minimisation.
    #[tracing::instrument(name = "dynamics.step_derivatives", level = "debug", skip_all)]
    pub fn step_with_derivatives(
        &mut self,
        x: &[f64],
        u: &[f64],
    ) -> Result<(Step, StepDerivatives), DynamicsError> {
        let lin = self.linearise(x, u, None, None)?;
        let der = self.first_derivatives(&lin);
        Ok((lin.step, der))
    }

    /// The exact derivatives of `step`, a step this simulator computed from `x` under `u` (by
    /// [`Simulator::step`] or a derivative call): its solution is linearised as it is, without solving the
    /// step again, so the derivatives belong to exactly the step the caller holds (and the warm start is
    /// left alone). A step computed from another `(x, u)` gives the derivatives of a wrong point; one with
    /// another number of rows is an error.
    #[tracing::instrument(name = "dynamics.derivatives_of", level = "debug", skip_all)]
    pub fn derivatives_of(
        &mut self,
        x: &[f64],
        u: &[f64],
        step: &Step,
    ) -> Result<StepDerivatives, DynamicsError> {
        let lin = self.linearise(x, u, None, Some(step))?;
        Ok(self.first_derivatives(&lin))
    }

    fn first_derivatives(&self, lin: &Linearised) -> StepDerivatives {
        let scene = self.scene();
        let (n, nu, h) = (scene.n_dof(), scene.n_controls, self.settings().h);
        let cols = 2 * n + nu;
        let dv = &lin.dp;
        let nx = 2 * n;
        let mut fx = vec![0.0; nx * nx];
        let mut fu = vec![0.0; nx * nu];
        for i in 0..n {
            for j in 0..nx {
                let d = dv[i * cols + j];
                fx[i * nx + j] = h * d + if i == j { 1.0 } else { 0.0 };
                fx[(n + i) * nx + j] = d;
            }
            for k in 0..nu {
                let d = dv[i * cols + nx + k];
                fu[i * nu + k] = h * d;
                fu[(n + i) * nu + k] = d;
            }
        }
        StepDerivatives { fx, fu }
    }

    /// One step, its first derivatives, and for a given `c` (length `2n`, the value gradient of DDP) the
    /// Hessian of `c^T f(x, u)` with respect to `y = (x, u)`, row-major `(2n + n_u)^2`: the `f_xx`, `f_xu`,
    /// `f_uu` terms contracted with `c`. [`Simulator::second_order_step`] then
    /// [`SecondOrderStep::hessian`]; use those directly to contract one step with several `c`.
    #[tracing::instrument(name = "dynamics.step_hessian", level = "debug", skip_all)]
    pub fn step_with_hessian(
        &mut self,
        x: &[f64],
        u: &[f64],
        c: &[f64],
    ) -> Result<(Step, StepDerivatives, Vec<f64>), DynamicsError> {
        let so = self.second_order_step(x, u)?;
        let hess = so.hessian(c)?;
        Ok((so.step, so.derivatives, hess))
    }

    /// One step, its first derivatives, and everything its second derivatives need except the vector
    /// they are contracted with (scenes of at most three joints and `2n + n_u <= 8`): the step's
    /// linearisation, the factors of `K_p^T`, and the ingredients in second-order duals. About three
    /// quarters of the work of [`Simulator::step_with_hessian`]; each [`SecondOrderStep::hessian`] is the
    /// rest.
    #[tracing::instrument(name = "dynamics.second_order_step", level = "debug", skip_all)]
    pub fn second_order_step(
        &mut self,
        x: &[f64],
        u: &[f64],
    ) -> Result<SecondOrderStep, DynamicsError> {
        self.second_order(x, u, None)
    }

    /// [`Simulator::second_order_step`] of `step`, a step this simulator computed from `x` under `u`: its
    /// solution is linearised as it is, without a second solve (see [`Simulator::derivatives_of`]).
    #[tracing::instrument(name = "dynamics.second_order_of", level = "debug", skip_all)]
    pub fn second_order_of(
        &mut self,
        x: &[f64],
        u: &[f64],
        step: &Step,
    ) -> Result<SecondOrderStep, DynamicsError> {
        self.second_order(x, u, Some(step))
    }

    fn second_order(
        &mut self,
        x: &[f64],
        u: &[f64],
        given: Option<&Step>,
    ) -> Result<SecondOrderStep, DynamicsError> {
        let (n, nu, h) = (
            self.scene().n_dof(),
            self.scene().n_controls,
            self.settings().h,
        );
        let cols = 2 * n + nu;
        if cols > DIRECTIONS || n > 3 {
            return Err(DynamicsError::Unsupported(
                "Hessians of scenes with more than 3 joints or 8 state and control entries",
            ));
        }
        check("x", x, 2 * n)?;
        check("u", u, nu)?;
        let ing = self.second_order_ingredients(x, u)?;
        let lin = self.linearise(x, u, Some(&ing), given)?;
        let derivatives = self.first_derivatives(&lin);
        let np = lin.p.len();
        let model = self.settings().model;
        let structured = match model {
            Complementarity::Hard => Some(0.0),
            Complementarity::Logistic { sigma } if !self.has_state_covariance() => Some(sigma),
            _ => None,
        };
        let equations = match structured {
            Some(sigma) => ing.equation_hessians(h, x, &lin.p, &lin.dp, cols, &lin.kinds, sigma),
            None => {
                // The general path: the equations in eight-direction second-order duals along T.
                let ps: Vec<D2> = (0..np)
                    .map(|i| {
                        let mut grad = SMatrix::<f64, 1, DIRECTIONS>::zeros();
                        for k in 0..cols {
                            grad[(0, k)] = lin.dp[i * cols + k];
                        }
                        D2::new(lin.p[i], Derivative::some(grad), Derivative::none())
                    })
                    .collect();
                let v: Vec<D2> = (0..n)
                    .map(|j| D2::from_re(x[n + j]).derivative(n + j))
                    .collect();
                let normal = matches!(model, Complementarity::Normal { .. });
                let mut e = vec![0.0; np * cols * cols];
                for (k, eq) in system(n, h, &ing.lifted(), &v, &ps, &lin.kinds, normal)
                    .iter()
                    .zip(e.chunks_exact_mut(cols * cols))
                {
                    if let Some(hm) = &k.v2.0 {
                        for i in 0..cols {
                            for j in 0..cols {
                                eq[i * cols + j] = hm[(i, j)];
                            }
                        }
                    }
                }
                e
            }
        };
        Ok(SecondOrderStep {
            step: lin.step,
            derivatives,
            n,
            cols,
            h,
            adjoint: std::cell::RefCell::new(lin.lu),
            equations,
        })
    }
}

/// A step prepared for its second derivatives ([`Simulator::second_order_step`]): the step, its first
/// derivatives, and the Hessian of `c^T f` for any `c` by [`SecondOrderStep::hessian`]. Second-order
/// adjoint: with `K_p^T mu = -g` for the step's equations `K(p; y) = 0` and `g = (dx'/dp)^T c`,
/// `d^2 (c^T f) / dy^2 = T^T (d^2 (mu^T K) / d(p, y)^2) T`, `T = [dp/dy; I]`, the inner Hessian along the
/// columns of `T` in one pass of second-order vector duals (`num_dual::Dual2SVec64`).
pub struct SecondOrderStep {
    /// The step.
    pub step: Step,
    /// Its first derivatives.
    pub derivatives: StepDerivatives,
    n: usize,
    cols: usize,
    h: f64,
    adjoint: std::cell::RefCell<DenseLu>,
    /// The Hessian of each of the step's equations along `T` (row-major `cols x cols` each, one after
    /// the other).
    equations: Vec<f64>,
}

impl std::fmt::Debug for SecondOrderStep {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SecondOrderStep")
            .field("step", &self.step)
            .field("derivatives", &self.derivatives)
            .finish_non_exhaustive()
    }
}

impl SecondOrderStep {
    /// The Hessian of `c^T f(x, u)` with respect to `(x, u)`, row-major `(2n + n_u)^2`.
    pub fn hessian(&self, c: &[f64]) -> Result<Vec<f64>, DynamicsError> {
        let (n, cols, h) = (self.n, self.cols, self.h);
        if c.len() != 2 * n || !c.iter().all(|e| e.is_finite()) {
            return Err(DynamicsError::Input {
                what: "c",
                problem: format!("needs {} finite entries", 2 * n),
            });
        }
        let np = self.equations.len() / (cols * cols);
        // g = (dx'/dp)^T c with x' = [q + h v'; v'], and mu from K_p^T mu = -g.
        let mut mu = vec![0.0; np];
        for i in 0..n {
            mu[i] = -(h * c[i] + c[n + i]);
        }
        self.adjoint.borrow_mut().solve_transposed(&mut mu);
        let mut hess = vec![0.0; cols * cols];
        for (e, w) in self.equations.chunks_exact(cols * cols).zip(&mu) {
            for (a, b) in hess.iter_mut().zip(e) {
                *a += w * b;
            }
        }
        // Symmetric to rounding; make it exactly so.
        for i in 0..cols {
            for j in 0..i {
                let v = 0.5 * (hess[i * cols + j] + hess[j * cols + i]);
                hess[i * cols + j] = v;
                hess[j * cols + i] = v;
            }
        }
        Ok(hess)
    }
}

/// What the linearisation of a step keeps.
struct Linearised {
    step: Step,
    /// The unknowns of the step's equations at the solution ([`system`]).
    p: Vec<f64>,
    /// The factors of `K_p`.
    lu: DenseLu,
    /// `dp/d(x, u)`, row-major `len(p) x (2n + n_u)`.
    dp: Vec<f64>,
    /// Each complementarity row's kind.
    kinds: Vec<RowKind>,
}

/// The logistic NCP function of paper eq. (17) in any dual type: `min(a, b) - s softplus(-|a - b| / s)`.
fn logistic<T: Scalar>(a: T, b: T, sigma: T) -> T {
    let c = (a - b) / sigma;
    if c.re() > 0.0 {
        b - (-c).exp().ln_1p() * sigma
    } else {
        a - c.exp().ln_1p() * sigma
    }
}
