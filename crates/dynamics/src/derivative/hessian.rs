//! Stage 3 of the derivatives: the second-order terms. With `K(p; y) = 0` the step's equations (stage 2)
//! and `K_p^T mu = -g` for `g = (dx'/dp)^T c`, `d^2 (c^T f) / dy^2 = T^T (d^2 (mu^T K) / d(p, y)^2) T` with
//! `T = [dp/dy; I]` (second-order adjoint). The Hessian of each equation along `T` is assembled from the
//! ingredients' expansions (stage 1): in plain arrays for the logistic and hard models with a constant
//! noise, in second-order vector duals otherwise (one pass per pair of blocks of directions beyond eight).

#![allow(non_snake_case)]

use super::StepDerivatives;
use super::expansion::{D2, DIRECTIONS, Expansion, block_pairs};
use super::linearise::{RowKind, Source, system};
use crate::error::DynamicsError;
use crate::step::{Complementarity, Model, Step};
use nalgebra::SMatrix;
use ncp::{DenseLu, NcpFunction};
use num_dual::Derivative;

impl Expansion {
    /// The Hessians in `s` of the logistic and hard models' equations `K_i(p0 + dp s, y0 + s)` with a
    /// constant sigma, row-major `cols x cols` each, assembled in plain arrays from the structure of
    /// [`system`] instead of in eight-direction duals: every product there is of a function of `q` alone
    /// (gradient and Hessian over the first `n` directions, from its expansion) and a function
    /// affine in `s`, and each row is a function of two such quantities (`lambda_i`, `w_i`).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn equation_hessians(
        &self,
        h: f64,
        x: &[f64],
        p: &[f64],
        dp: &[f64],
        cols: usize,
        kinds: &[RowKind],
        sigma: f64,
    ) -> Vec<f64> {
        // The finger's sizes compiled in (the same arithmetic, its loops unrolled); any other at run time.
        match (self.n, cols) {
            (3, 8) => self.equation_hessians_sized::<3, 8>(h, x, p, dp, kinds, sigma),
            _ => self.equation_hessians_sized::<0, 0>(h, x, p, dp, kinds, sigma),
        }
    }

    /// [`Expansion::equation_hessians`] with `N` joints and `C` columns when they are not 0.
    #[allow(clippy::too_many_arguments)]
    fn equation_hessians_sized<const N: usize, const C: usize>(
        &self,
        h: f64,
        x: &[f64],
        p: &[f64],
        dp: &[f64],
        kinds: &[RowKind],
        sigma: f64,
    ) -> Vec<f64> {
        let n = if N > 0 { N } else { self.n };
        let cols = if C > 0 { C } else { dp.len() / p.len() };
        let m = self.m;
        let geo = &self.geometry;
        let cc = cols * cols;
        // Every Hessian below is symmetric: only its upper triangle is accumulated, and each is mirrored
        // once at the end.
        // out += scale * H_q(f) in the leading n x n block.
        let add_q = |out: &mut [f64], f: usize, scale: f64| {
            for (r, (o, hf)) in out
                .chunks_exact_mut(cols)
                .zip(geo.h(f).chunks_exact(n))
                .enumerate()
            {
                for (o, e) in o[r..n].iter_mut().zip(&hf[r..]) {
                    *o += scale * e;
                }
            }
        };
        // out += scale * (a b^T + b a^T), a over the first n directions.
        let add_sym = |out: &mut [f64], a: &[f64], b: &[f64], scale: f64| {
            for (i, &a) in a.iter().enumerate() {
                let ai = scale * a;
                if ai == 0.0 {
                    continue;
                }
                for (j, &b) in b[..i].iter().enumerate() {
                    out[j * cols + i] += ai * b;
                }
                out[i * cols + i] += 2.0 * ai * b[i];
                for (o, &b) in out[i * cols + i + 1..(i + 1) * cols]
                    .iter_mut()
                    .zip(&b[i + 1..])
                {
                    *o += ai * b;
                }
            }
        };
        let row = |i: usize| &dp[i * cols..(i + 1) * cols];
        let mut out = vec![0.0; (n + m) * cc];
        let mut dl = vec![0.0; cols];
        let mut hw = vec![0.0; cc];
        let mut gw = vec![0.0; cols];
        // Equations of motion: sum_j M_ij (v'_j - v_j) - h r_i - sum_k J_ki lambda_k.
        for i in 0..n {
            let e = &mut out[i * cc..(i + 1) * cc];
            for j in 0..n {
                let f = self.mass(i, j);
                dl.copy_from_slice(row(j));
                dl[n + j] -= 1.0;
                add_q(e, f, p[j] - x[n + j]);
                add_sym(e, geo.g(f), &dl, 1.0);
            }
            for k in 0..m {
                let f = self.jac(k, i);
                add_q(e, f, -p[n + k]);
                add_sym(e, geo.g(f), row(n + k), -1.0);
            }
            let (hm, dim) = (self.forces.h(i), self.forces.dim());
            for a in 0..dim {
                for b in a..dim {
                    e[a * cols + b] -= h * hm[a * dim + b];
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
            let gd = geo.g(self.dist(k));
            add_q(&mut hw, self.dist(k), 1.0 / h);
            for i in 0..n {
                gw[i] += gd[i] / h;
            }
            for j in 0..n {
                let f = self.jac(k, j);
                let gf = geo.g(f);
                add_q(&mut hw, f, p[j]);
                add_sym(&mut hw, gf, row(j), 1.0);
                for i in 0..n {
                    gw[i] += p[j] * gf[i];
                }
                let re = geo.re(f);
                for (g, d) in gw.iter_mut().zip(row(j)) {
                    *g += re * d;
                }
            }
            let e = &mut out[(n + k) * cc..(n + k + 1) * cc];
            match kinds[k] {
                RowKind::Contact => e.copy_from_slice(&hw),
                RowKind::Logistic => {
                    let w0 = geo.re(self.dist(k)) / h
                        + (0..n).map(|j| geo.re(self.jac(k, j)) * p[j]).sum::<f64>();
                    let jet = NcpFunction::Logistic { sigma }.jet(p[n + k], w0);
                    let gl = row(n + k);
                    for a in 0..cols {
                        for b in a..cols {
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
        for e in out.chunks_exact_mut(cc) {
            for a in 1..cols {
                for b in 0..a {
                    e[a * cols + b] = e[b * cols + a];
                }
            }
        }
        out
    }
}

impl Model {
    pub(super) fn second_order_from(
        &self,
        x: &[f64],
        u: &[f64],
        mut source: Source<'_>,
    ) -> Result<SecondOrderStep, DynamicsError> {
        let (n, nu, h) = (
            self.scene().n_dof(),
            self.scene().n_controls,
            self.settings().h,
        );
        let cols = 2 * n + nu;
        let ing = self.expansion(x, u)?;
        let lin = self.linearise(x, u, Some(&ing), &mut source)?;
        let derivatives = self.first_derivatives(&lin);
        let model = self.settings().model;
        let structured = match model {
            Complementarity::Hard => Some(0.0),
            Complementarity::Logistic { sigma } if !self.has_state_covariance() => Some(sigma),
            _ => None,
        };
        let equations = match structured {
            Some(sigma) => ing.equation_hessians(h, x, &lin.p, &lin.dp, cols, &lin.kinds, sigma),
            None => {
                let normal = matches!(model, Complementarity::Normal { .. });
                general_hessians(&ing, h, x, &lin, cols, normal)
            }
        };
        Ok(SecondOrderStep {
            step: source.data().step().expect("linearised above").clone(),
            derivatives,
            n,
            cols,
            h,
            adjoint: std::cell::RefCell::new(lin.lu),
            equations,
        })
    }
}

/// The Hessians along `T` of the step's equations ([`system`]) in second-order vector duals: one pass
/// when `y` has at most eight entries, otherwise one pass per pair of blocks of four directions.
fn general_hessians(
    ing: &Expansion,
    h: f64,
    x: &[f64],
    lin: &super::linearise::Linearised,
    cols: usize,
    normal: bool,
) -> Vec<f64> {
    let n = ing.n;
    let np = lin.p.len();
    let passes = block_pairs(cols, DIRECTIONS);
    let cc = cols * cols;
    let mut e = vec![0.0; np * cc];
    for dirs in &passes {
        let ps: Vec<D2> = (0..np)
            .map(|i| {
                let mut grad = SMatrix::<f64, 1, DIRECTIONS>::zeros();
                for (l, &k) in dirs.iter().enumerate() {
                    grad[(0, l)] = lin.dp[i * cols + k];
                }
                D2::new(lin.p[i], Derivative::some(grad), Derivative::none())
            })
            .collect();
        let v: Vec<D2> = (0..n)
            .map(|j| {
                let d = D2::from_re(x[n + j]);
                match dirs.iter().position(|&k| k == n + j) {
                    Some(l) => d.derivative(l),
                    None => d,
                }
            })
            .collect();
        for (k, eq) in system(n, h, &ing.lifted(dirs), &v, &ps, &lin.kinds, normal)
            .iter()
            .zip(e.chunks_exact_mut(cc))
        {
            if let Some(hm) = &k.v2.0 {
                for (l, &i) in dirs.iter().enumerate() {
                    for (l2, &j) in dirs.iter().enumerate() {
                        eq[i * cols + j] = hm[(l, l2)];
                    }
                }
            }
        }
    }
    e
}

/// A step prepared for its second derivatives ([`Simulator::second_order_step`]): the step, its first
/// derivatives, and the Hessian of `c^T f` for any `c` by [`SecondOrderStep::hessian`]. Second-order
/// adjoint: with `K_p^T mu = -g` for the step's equations `K(p; y) = 0` and `g = (dx'/dp)^T c`,
/// `d^2 (c^T f) / dy^2 = T^T (d^2 (mu^T K) / d(p, y)^2) T`, `T = [dp/dy; I]`, the inner Hessian along the
/// columns of `T` (stage 3, module documentation).
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Scene, Simulator, StepSettings};

    /// The structured equation Hessians and the dual path (one pass, or one per pair of blocks of four
    /// directions) for the same step and `c`.
    fn both(sim: &mut Simulator, x: &[f64], u: &[f64], c: &[f64]) -> (Vec<f64>, Vec<f64>, f64) {
        let structured = sim.second_order_step(x, u).unwrap();
        let ing = sim.model().expansion(x, u).unwrap();
        let lin = sim
            .model()
            .linearise(x, u, Some(&ing), &mut Source::Stored(sim.data()))
            .unwrap();
        let (n, cols, h) = (structured.n, structured.cols, structured.h);
        let equations = general_hessians(&ing, h, x, &lin, cols, false);
        let step = sim.data().step().unwrap().clone();
        let lambda = step.lambda.iter().fold(0.0f64, |a, &b| a.max(b));
        let general = SecondOrderStep {
            step,
            derivatives: structured.derivatives.clone(),
            n,
            cols,
            h,
            adjoint: std::cell::RefCell::new(lin.lu),
            equations,
        };
        (
            structured.hessian(c).unwrap(),
            general.hessian(c).unwrap(),
            lambda,
        )
    }

    fn agree(sim: &mut Simulator, states: &[Vec<f64>], u: &[f64]) -> usize {
        let n = sim.scene().n_dof();
        let c: Vec<f64> = (0..2 * n)
            .map(|i| ((i * 7 + 3) % 5) as f64 * 0.2 - 0.4)
            .collect();
        let mut touching = 0;
        for x in states {
            let (a, b, lambda) = both(sim, x, u, &c);
            let scale = b.iter().fold(1.0f64, |m, v| m.max(v.abs()));
            for (i, (p, q)) in a.iter().zip(&b).enumerate() {
                assert!(
                    (p - q).abs() <= 1e-9 * scale,
                    "entry {i} at {x:?}: structured {p} vs duals {q}"
                );
            }
            touching += usize::from(lambda > 1e-3);
        }
        touching
    }

    #[test]
    fn the_structured_hessian_is_the_dual_one_for_the_finger_and_a_four_joint_scene() {
        let finger: Vec<Vec<f64>> = (0..24)
            .map(|i| {
                let t = i as f64 * 0.26;
                vec![
                    -1.0 - 0.3 * t.sin(),
                    -0.8 + 0.2 * t.cos(),
                    t,
                    0.5 * t.sin(),
                    -0.3,
                    1.0,
                ]
            })
            .collect();
        for model in [
            Complementarity::Logistic { sigma: 0.1 },
            Complementarity::Logistic { sigma: 0.3 },
            Complementarity::Hard,
        ] {
            let settings = StepSettings {
                model,
                ..StepSettings::default()
            };
            let mut sim = Simulator::new(Scene::flicking_finger(), settings).unwrap();
            assert!(
                agree(&mut sim, &finger, &[0.3, -0.2]) > 0,
                "{model:?}: no contact"
            );
        }
        // A third link: 4 joints, 3 controls, 11 directions (six pairs of blocks in duals).
        let mut spec = Scene::flicking_finger().spec().clone();
        let mut link = spec.bodies[1].clone();
        link.name = "link3".into();
        link.parent = "link2".into();
        link.semi_axes = [0.5, 0.2];
        link.centre = [0.5, 0.0];
        link.joint.limits = None;
        spec.bodies.insert(2, link);
        let mut pair = spec.contacts[0].clone();
        pair.a = "link3".into();
        spec.contacts.push(pair);
        let scene = Scene::new(spec).unwrap();
        let settings = StepSettings {
            model: Complementarity::Logistic { sigma: 0.2 },
            ..StepSettings::default()
        };
        let mut sim = Simulator::new(scene, settings).unwrap();
        let states: Vec<Vec<f64>> = (0..12)
            .map(|i| {
                let t = i as f64 * 0.5;
                vec![-1.0, -0.9 - 0.2 * t.cos(), -0.6, t, 0.3, -0.2, 0.1, 1.0]
            })
            .collect();
        assert!(
            agree(&mut sim, &states, &[0.2, -0.1, 0.3]) > 0,
            "no contact"
        );
    }
}
