//! The derivative stages as methods of the step's [`Model`], and the owned [`SecondOrderStep`]: the entry
//! points check their inputs once and run the stages (`expansion`, `linearise`, `hessian`) on the step a
//! [`StepData`] holds or solves, keeping the result in the data ([`Model::calc_diff`],
//! [`Model::calc_diff2_prepare`], [`Model::calc_diff2`]) or handing out a copy. The stages' own files hold
//! data and arithmetic only and import nothing of the step, so that the step's data can hold what they
//! compute.

#![allow(non_snake_case)]

use super::StepDerivatives;
use super::data::{DerivativeData, Duals, Values, Work};
use super::expansion::{D1, DIRECTIONS, Expansion, F1, Ingredients, Sink, Taylor, jet1_dual};
use super::hessian::{Equations, SecondOrderParts, correction_hessians, general_hessians};
use super::linearise::{Linearised, RowKind, System, system_into};
use crate::constraint::{Constraints, ContactFrame};
use crate::error::DynamicsError;
use crate::jet::Jet;
use crate::kinematics::{ForceScratch, Kinematics, Ring};
use crate::step::{Complementarity, Model, PrepareScratch, Step, StepData, Stored, check};
use ncp::{DenseLu, LinearSolver, Mcp, NcpFunction, normal_expected_squared};
use std::any::Any;

thread_local! {
    /// The derivative stages' working vectors, one set per thread: they hold nothing from one call to the
    /// next, so the knots of a trajectory share them (kept hot in the cache) instead of each keeping its
    /// own, and after the first calls nothing is allocated.
    static WORK: std::cell::RefCell<Work> = std::cell::RefCell::new(Work::default());
}

/// `f` with this thread's working vectors (fresh ones should it be called from inside `f`).
fn with_work<R>(f: impl FnOnce(&mut Work) -> R) -> R {
    WORK.with(|work| match work.try_borrow_mut() {
        Ok(mut work) => f(&mut work),
        Err(_) => f(&mut Work::default()),
    })
}

/// Why a data without a step has no derivatives.
fn no_step() -> DynamicsError {
    DynamicsError::Input {
        what: "step data",
        problem: "holds no step to linearise (compute one with Model::step first)".into(),
    }
}

impl Model {
    /// An estimate, before anything is allocated, of the bytes one step's second-order expansion
    /// ([`Model::second_order`]) holds: the second-order Taylor expansions of `M`, `J`, `d` and the
    /// noise over `q` and of the forces over `(q, v)`, and the Hessians of the step's equations over
    /// `(x, u)`. An optimiser that keeps one per knot needs this times its knots.
    pub fn second_order_bytes(&self) -> usize {
        let scene = self.scene();
        let (n, m, nu) = (scene.n_dof(), scene.n_constraints(), scene.n_controls);
        let taylor = |len: usize, dim: usize| len.saturating_mul(1 + dim + dim.saturating_mul(dim));
        let cols = 2 * n + nu;
        let doubles = taylor(n * n + m * n + 2 * m, n)
            .saturating_add(taylor(n, 2 * n))
            .saturating_add(
                (n + m)
                    .saturating_mul(cols)
                    .saturating_mul(cols)
                    .saturating_mul(2),
            );
        doubles.saturating_mul(std::mem::size_of::<f64>())
    }

    /// The first derivatives of the step `data` holds ([`Model::derivatives`]), kept in `data` (and read
    /// from it when [`Model::calc_diff2_prepare`] computed them already) until its next step: the
    /// first-order stage of the optimiser's knots, without copying.
    pub fn calc_diff<'d>(
        &self,
        data: &'d mut StepData,
    ) -> Result<&'d StepDerivatives, DynamicsError> {
        let (stored, diff) = self.stored_and_derivatives(data)?;
        if !diff.has_first {
            let DerivativeData {
                first,
                has_first,
                parts,
                has_second,
            } = diff;
            // The linearisation is the second-order parts' own: they no longer belong to this step.
            *has_second = false;
            let (x, u) = (stored.x, stored.u);
            let lin = &mut parts.lin;
            with_work(|work| self.linearise(x, u, None, &mut Source::Stored(stored), lin, work))?;
            self.first_derivatives_into(&parts.lin, first);
            *has_first = true;
        }
        Ok(&diff.first)
    }

    /// Keep in `data` the first derivatives of the step it holds and everything its second derivatives
    /// need except the vector they are contracted with ([`Model::second_order`], without copying the
    /// step), each refilled in place; nothing when they are kept already. Each [`Model::calc_diff2`] is
    /// then the contraction.
    pub fn calc_diff2_prepare(&self, data: &mut StepData) -> Result<(), DynamicsError> {
        let (stored, diff) = self.stored_and_derivatives(data)?;
        if !diff.has_second {
            (diff.has_first, diff.has_second) = (false, false);
            let (x, u) = (stored.x, stored.u);
            self.second_order_parts(x, u, Source::Stored(stored), diff)?;
            (diff.has_first, diff.has_second) = (true, true);
        }
        Ok(())
    }

    /// The Hessian of `c^T f(x, u)` with respect to `y = (x, u)` for the step `data` holds, into `hess`
    /// (row-major `(2n + n_u)^2`), and its first derivatives: [`Model::calc_diff2_prepare`] (if it has
    /// not run since the step) and the contraction with `c` ([`SecondOrderStep::hessian`]).
    pub fn calc_diff2<'d>(
        &self,
        data: &'d mut StepData,
        c: &[f64],
        hess: &mut [f64],
    ) -> Result<&'d StepDerivatives, DynamicsError> {
        self.calc_diff2_prepare(data)?;
        data.diff.parts.hessian_into(c, hess)?;
        Ok(&data.diff.first)
    }

    /// The exact derivatives of the step `data` holds (the last [`Model::step`] computed with it), at the
    /// `(x, u)` it was computed from: its solution is linearised as it is, never solved again, so the
    /// derivatives belong to exactly that step. For every model: the hard model's are its active set's
    /// (module documentation), the normal model's those of the first-order conditions of its minimisation.
    /// `Err` when `data` holds no step.
    #[tracing::instrument(name = "dynamics.derivatives", level = "debug", skip_all)]
    pub fn derivatives(&self, data: &StepData) -> Result<StepDerivatives, DynamicsError> {
        let stored = self.stored(data)?;
        let mut diff = DerivativeData::default();
        let (x, u) = (stored.x, stored.u);
        let lin = &mut diff.parts.lin;
        with_work(|work| self.linearise(x, u, None, &mut Source::Stored(stored), lin, work))?;
        self.first_derivatives_into(lin, &mut diff.first);
        Ok(diff.first)
    }

    /// One step from `x` under `u` in `data` (as [`Model::step`]) and its exact derivatives, the geometry
    /// evaluated once for both.
    #[tracing::instrument(name = "dynamics.step_derivatives", level = "debug", skip_all)]
    pub fn step_with_derivatives(
        &self,
        data: &mut StepData,
        x: &[f64],
        u: &[f64],
    ) -> Result<StepDerivatives, DynamicsError> {
        self.check_point(data, x, u)?;
        let mut diff = DerivativeData::default();
        let lin = &mut diff.parts.lin;
        with_work(|work| self.linearise(x, u, None, &mut Source::Solve(data), lin, work))?;
        self.first_derivatives_into(lin, &mut diff.first);
        Ok(diff.first)
    }

    /// The step `data` holds; `Err` for data of another model or holding no step.
    fn stored<'d>(&self, data: &'d StepData) -> Result<Stored<'d>, DynamicsError> {
        self.check_data(data)?;
        data.stored().ok_or_else(no_step)
    }

    /// [`Model::stored`], and beside it the derivatives `data` keeps.
    fn stored_and_derivatives<'d>(
        &self,
        data: &'d mut StepData,
    ) -> Result<(Stored<'d>, &'d mut DerivativeData), DynamicsError> {
        self.check_data(data)?;
        match data.stored_and_derivatives() {
            (Some(stored), diff) => Ok((stored, diff)),
            (None, _) => Err(no_step()),
        }
    }

    /// `Err` for data of another model, or an `x` or `u` of the wrong length or not finite.
    fn check_point(&self, data: &StepData, x: &[f64], u: &[f64]) -> Result<(), DynamicsError> {
        self.check_data(data)?;
        check("x", x, self.scene().n_state())?;
        check("u", u, self.scene().n_controls)
    }

    /// `fx` and `fu` from the linearisation, into `out` (refilled).
    fn first_derivatives_into(&self, lin: &Linearised, out: &mut StepDerivatives) {
        let scene = self.scene();
        let (n, nu, h) = (scene.n_dof(), scene.n_controls, self.settings().h);
        let cols = 2 * n + nu;
        let dv = &lin.dp;
        let nx = 2 * n;
        let StepDerivatives { fx, fu } = out;
        fx.clear();
        fx.resize(nx * nx, 0.0);
        fu.clear();
        fu.resize(nx * nu, 0.0);
        let dc = &lin.dcorrection;
        for i in 0..n {
            for j in 0..nx {
                let d = dv[i * cols + j];
                fx[i * nx + j] = h * d + dc[i * cols + j] + if i == j { 1.0 } else { 0.0 };
                fx[(n + i) * nx + j] = d;
            }
            for k in 0..nu {
                let d = dv[i * cols + nx + k];
                fu[i * nu + k] = h * d + dc[i * cols + nx + k];
                fu[(n + i) * nu + k] = d;
            }
        }
    }

    /// The first derivatives of the step `data` holds and everything its second derivatives need except
    /// the vector they are contracted with (any scene): the step's linearisation, the factors of `K_p^T`,
    /// and the Hessians of the step's equations (for the logistic and hard models with a constant noise,
    /// what they are made of). Each [`SecondOrderStep::hessian`] is the rest. Linearises the stored step
    /// as [`Model::derivatives`] does; `Err` when `data` holds no step.
    #[tracing::instrument(name = "dynamics.second_order", level = "debug", skip_all)]
    pub fn second_order(&self, data: &StepData) -> Result<SecondOrderStep, DynamicsError> {
        let stored = self.stored(data)?;
        self.second_order_from(stored.x, stored.u, Source::Stored(stored))
    }

    /// One step from `x` under `u` in `data` (as [`Model::step`]) and its [`Model::second_order`], the
    /// geometry evaluated once for both.
    #[tracing::instrument(name = "dynamics.second_order_step", level = "debug", skip_all)]
    pub fn second_order_step(
        &self,
        data: &mut StepData,
        x: &[f64],
        u: &[f64],
    ) -> Result<SecondOrderStep, DynamicsError> {
        self.check_point(data, x, u)?;
        self.second_order_from(x, u, Source::Solve(data))
    }
}

impl Model {
    /// Each row's noise in the scalar type of `jac`: the model's constant, or eq. (18) through `J(q)`.
    pub(super) fn noise<T: crate::kinematics::Ring>(&self, jac: &[T], m: usize) -> Vec<T> {
        let mut out = Vec::new();
        self.noise_into(jac, m, &mut out);
        out
    }

    /// [`Model::noise`] into `out` (refilled; no allocation for a constant noise once sized).
    fn noise_into<T: crate::kinematics::Ring>(&self, jac: &[T], m: usize, out: &mut Vec<T>) {
        use crate::step::{Complementarity, row_sigmas};
        let sigma = match self.settings().model {
            Complementarity::Hard => 0.0,
            Complementarity::Logistic { sigma } | Complementarity::Normal { sigma } => sigma,
        };
        out.clear();
        match self.state_covariance() {
            Some(cov) => out.extend(row_sigmas(
                cov,
                jac,
                self.scene().n_dof(),
                self.settings().h,
                sigma,
            )),
            None => out.resize(m, T::from(sigma)),
        }
    }

    /// The ingredients in first-order duals over `y[first..first + 8]`, into `out` (refilled), the jets
    /// they are computed in among `jets`; the contacts finish from `seeds`, the step's own at `x`, when
    /// given.
    fn first_order_ingredients(
        &self,
        (x, u): (&[f64], &[f64]),
        first: usize,
        seeds: Option<&[ContactFrame]>,
        jets: &mut Vec<Box<dyn Any + Send>>,
        out: &mut Ingredients<D1>,
    ) -> Result<(), DynamicsError> {
        let scene = self.scene();
        let (n, m) = (scene.n_dof(), scene.n_constraints());
        let JetWork { args: ys, ing: w } = jet_work::<F1>(jets, (n, m));
        ys.clear();
        ys.extend(x.iter().chain(u).enumerate().map(|(j, &e)| {
            if (first..first + DIRECTIONS).contains(&j) {
                F1::variable(e, j - first)
            } else {
                F1::from(e)
            }
        }));
        let (xs, us) = ys.split_at(2 * n);
        self.geometry_into(&xs[..n], seeds, w)?;
        let (kin, cons) = (w.kin.as_ref(), w.cons.as_ref());
        let (kin, cons) = (kin.expect("made above"), cons.expect("made above"));
        kin.applied_forces_into(scene, &xs[n..], us, &mut w.r, &mut w.forces);
        let dual = |out: &mut Vec<D1>, v: &[F1]| {
            out.clear();
            out.extend(v.iter().map(jet1_dual));
        };
        out.contacts.clear();
        out.contacts.extend_from_slice(&cons.contacts);
        out.distance.clear();
        out.distance.extend_from_slice(&w.distance);
        dual(&mut out.M, &w.M);
        dual(&mut out.r, &w.r);
        dual(&mut out.jac, &cons.jacobian);
        dual(&mut out.d, &cons.d);
        dual(&mut out.sigma, &w.sigma);
        dual(&mut out.correction, &w.correction);
        Ok(())
    }

    /// The kinematics, rows, noise, mass matrix and position correction at `q` in `w`'s vectors, as the
    /// step sees them ([`Model::prepare_ingredients_into`]); the contacts finish from `seeds`, the step's
    /// own contacts at `q`'s values, when given ([`Constraints::update_seeded`]).
    fn geometry_into<T: Ring>(
        &self,
        q: &[T],
        seeds: Option<&[ContactFrame]>,
        w: &mut JetIngredients<T>,
    ) -> Result<(), DynamicsError> {
        let scene = self.scene();
        let kin = Kinematics::refresh(&mut w.kin, scene, q);
        let cons = Constraints::refresh_seeded(&mut w.cons, scene, kin, q, seeds)?;
        self.noise_into(&cons.jacobian, cons.d.len(), &mut w.sigma);
        kin.mass_matrix_into(scene, &mut w.M);
        self.prepare_ingredients_into(
            &mut w.M,
            &cons.jacobian,
            &mut cons.d,
            (&mut w.distance, &mut w.correction),
            &mut w.prepare,
        )
    }

    /// The geometry `[M; J; d; noise; correction]` of `q` in any jet into the sink, computed in `w`'s
    /// vectors; on the first pass the contact frames and true distances into `contacts` and `distance`.
    fn geometry<const K: usize, const H: usize>(
        &self,
        q: &[Jet<K, H>],
        seeds: Option<&[ContactFrame]>,
        w: &mut JetIngredients<Jet<K, H>>,
        (contacts, distance): (&mut Vec<ContactFrame>, &mut Vec<f64>),
        sink: &mut Sink<'_>,
    ) -> Result<(), DynamicsError> {
        self.geometry_into(q, seeds, w)?;
        let cons = w.cons.as_ref().expect("made above");
        if sink.first() {
            contacts.clear();
            contacts.extend_from_slice(&cons.contacts);
            distance.clear();
            distance.extend_from_slice(&w.distance);
        }
        sink.emit(&w.M);
        sink.emit(&cons.jacobian);
        sink.emit(&cons.d);
        sink.emit(&w.sigma);
        sink.emit(&w.correction);
        Ok(())
    }

    /// The forces `r(q, v) + B u` of `(q, v)` in any jet, `u` held constant, into `w.r`: of the whole
    /// scene, or for the coordinates of one kinematic tree ([`Kinematics::tree_forces_into`]).
    fn forces<const K: usize, const H: usize>(
        &self,
        qv: &[Jet<K, H>],
        u: &[f64],
        tree: Option<usize>,
        w: &mut JetIngredients<Jet<K, H>>,
    ) {
        let scene = self.scene();
        let n = scene.n_dof();
        w.u.clear();
        w.u.extend(u.iter().map(|&e| Jet::from(e)));
        let kin = Kinematics::refresh(&mut w.kin, scene, &qv[..n]);
        let (v, r, scratch) = (&qv[n..], &mut w.r, &mut w.forces);
        match tree {
            None => kin.applied_forces_into(scene, v, &w.u, r, scratch),
            Some(t) => kin.tree_forces_into(scene, t, (v, &w.u), r, scratch),
        }
    }

    /// The second-order ingredients at `(x, u)`, any number of joints: the geometry over the joint angles
    /// and the forces over `(q, v)`, to be lifted to `y`. Three joints (the finger) take one pass of
    /// three-direction jets for the geometry and one of six for the forces; up to six joints, one pass
    /// each. Into `out`, refilled in place, the jets' working vectors among `jets`; the contacts finish
    /// from `seeds`, the step's own at `x`, when given.
    pub(super) fn expansion(
        &self,
        (x, u): (&[f64], &[f64]),
        seeds: Option<&[ContactFrame]>,
        out: &mut Expansion,
        jets: &mut Vec<Box<dyn Any + Send>>,
    ) -> Result<(), DynamicsError> {
        let scene = self.scene();
        let n = scene.n_dof();
        let m = scene.n_constraints();
        let len = n * n + m * n + 2 * m + n;
        let Expansion {
            contacts,
            distance,
            actuated,
            geometry,
            forces,
            over,
            ..
        } = out;
        // The narrowest jet that holds all of a group's arguments, so that one pass gives its Hessians
        // (each entry's arithmetic is the same in any width: the same numbers to the last bit); past
        // the widest, passes over pairs of blocks.
        macro_rules! geometry_in {
            ($k:literal, $h:literal) => {{
                let JetWork { args, ing } = jet_work::<Jet<$k, $h>>(jets, (n, m));
                Taylor::expand::<$k, $h>(geometry, &x[..n], len, args, |q, sink| {
                    self.geometry(q, seeds, ing, (&mut *contacts, &mut *distance), sink)
                })?
            }};
        }
        macro_rules! forces_in {
            ($k:literal, $h:literal) => {{
                let JetWork { args, ing } = jet_work::<Jet<$k, $h>>(jets, (n, m));
                Taylor::expand::<$k, $h>(forces, &x[..2 * n], n, args, |qv, sink| {
                    self.forces(qv, u, None, ing);
                    sink.emit(&ing.r);
                    Ok(())
                })?
            }};
        }
        match n {
            0..=3 => geometry_in!(3, 6),
            4 => geometry_in!(4, 10),
            5 => geometry_in!(5, 15),
            6 => geometry_in!(6, 21),
            _ => geometry_in!(8, 36),
        };
        let trees = scene.trees();
        if trees.len() == 1 {
            match 2 * n {
                0..=6 => forces_in!(6, 21),
                7..=8 => forces_in!(8, 36),
                9..=10 => forces_in!(10, 55),
                _ => forces_in!(12, 78),
            };
        } else {
            // The trees' forces are independent (no coordinate of one moves a body of another): each
            // tree's, over its own coordinates and velocities, in the narrowest jet that holds them;
            // the entries between trees stay zero.
            forces.zeroed(2 * n, n);
            for (t, tree) in trees.iter().enumerate() {
                over.clear();
                over.extend(&tree.coordinates);
                over.extend(tree.coordinates.iter().map(|&j| n + j));
                macro_rules! tree_forces_in {
                    ($k:literal, $h:literal) => {{
                        let JetWork { args, ing } = jet_work::<Jet<$k, $h>>(jets, (n, m));
                        Taylor::expand_over::<$k, $h>(
                            forces,
                            &x[..2 * n],
                            (over, &tree.coordinates),
                            args,
                            |qv, sink| {
                                self.forces(qv, u, Some(t), ing);
                                sink.emit(&ing.r);
                                Ok(())
                            },
                        )?
                    }};
                }
                match over.len() {
                    0 => {}
                    1..=2 => tree_forces_in!(2, 3),
                    3..=4 => tree_forces_in!(4, 10),
                    5..=6 => tree_forces_in!(6, 21),
                    7..=8 => tree_forces_in!(8, 36),
                    9..=10 => tree_forces_in!(10, 55),
                    _ => tree_forces_in!(12, 78),
                }
            }
        }
        actuated.clear();
        actuated.extend(
            scene
                .coordinates
                .iter()
                .enumerate()
                .filter_map(|(j, c)| c.actuator.map(|k| (j, 2 * n + k))),
        );
        (out.n, out.m) = (n, out.distance.len());
        Ok(())
    }
}

/// The working vectors of the passes in one scalar type `T` (a jet of some width, [`Model::expansion`]; or
/// the first-order jets of [`Model::first_order_ingredients`]), among the thread's working vectors: the
/// arguments and the ingredients computed from them.
struct JetWork<T> {
    args: Vec<T>,
    ing: JetIngredients<T>,
}

/// The geometry's and the forces' vectors in the scalar `T`.
struct JetIngredients<T> {
    kin: Option<Kinematics<T>>,
    cons: Option<Constraints<T>>,
    M: Vec<T>,
    sigma: Vec<T>,
    correction: Vec<T>,
    distance: Vec<f64>,
    prepare: PrepareScratch<T>,
    u: Vec<T>,
    r: Vec<T>,
    forces: ForceScratch<T>,
}

/// The working vectors of scalar `T` among `jets`, made the first time that scalar is used (for a scene
/// of `n` coordinates and `m` rows).
fn jet_work<T: Send + 'static>(
    jets: &mut Vec<Box<dyn Any + Send>>,
    (n, m): (usize, usize),
) -> &mut JetWork<T> {
    let at = match jets.iter().position(|w| w.is::<JetWork<T>>()) {
        Some(at) => at,
        None => {
            jets.push(Box::new(JetWork::<T> {
                args: Vec::new(),
                ing: JetIngredients {
                    kin: None,
                    cons: None,
                    M: Vec::new(),
                    sigma: Vec::new(),
                    correction: Vec::new(),
                    distance: Vec::new(),
                    prepare: PrepareScratch::for_size(n, m),
                    u: Vec::new(),
                    r: Vec::new(),
                    forces: ForceScratch::default(),
                },
            }));
            jets.len() - 1
        }
    };
    jets[at]
        .downcast_mut()
        .expect("of this width (found above)")
}

/// Where the step to linearise comes from. The public entry points check the data (and, to solve, `x` and
/// `u`) once; the stages below trust them.
pub(super) enum Source<'a> {
    /// Solve it now in this data (the ingredients' values make its problem: the geometry runs once).
    Solve(&'a mut StepData),
    /// The step a data holds, linearised as it is (no second solve).
    Stored(Stored<'a>),
}

impl Source<'_> {
    /// The applied forces of the step's data.
    fn forces(&self) -> &[f64] {
        match self {
            Source::Solve(data) => data.forces(),
            Source::Stored(stored) => stored.forces,
        }
    }

    /// The step, once it is solved.
    fn step(&self) -> Option<&Step> {
        match self {
            Source::Solve(data) => data.step(),
            Source::Stored(stored) => Some(stored.step),
        }
    }
}

impl Model {
    /// The step, the Jacobian of its equations in their unknowns and `dp/d(x, u)`, into `lin` (refilled
    /// in place), the working vectors in `work`. With `second` (the Hessian pass computes them anyway)
    /// the first-order ingredients are read off it.
    pub(super) fn linearise(
        &self,
        x: &[f64],
        u: &[f64],
        second: Option<&Expansion>,
        source: &mut Source<'_>,
        lin: &mut Linearised,
        work: &mut Work,
    ) -> Result<(), DynamicsError> {
        let model = self.settings().model;
        if self.has_state_covariance() && matches!(model, Complementarity::Normal { .. }) {
            return Err(DynamicsError::Unsupported(
                "derivatives of the normal model with per-row noise from a state covariance",
            ));
        }
        let (n, nu) = (self.scene().n_dof(), self.scene().n_controls);
        let cols = 2 * n + nu;
        // With the second-order expansion of a logistic or hard step with a constant noise, the
        // equations' derivatives in y are read off the ingredients' gradients directly; otherwise the
        // ingredients run in first-order duals, eight directions of y per pass.
        let direct = second.filter(|_| {
            !self.has_state_covariance() && !matches!(model, Complementarity::Normal { .. })
        });
        let Work {
            values,
            jets,
            first_order: passes,
            duals,
        } = work;
        if direct.is_none() {
            // A stored step computed its contacts at this `x`: each pass finishes from them.
            let step = match &*source {
                Source::Stored(stored) => Some(stored.step),
                Source::Solve(_) => None,
            };
            let seeds = step.map(|s| s.contacts.as_slice());
            let count = cols.div_ceil(DIRECTIONS);
            passes.truncate(count);
            passes.resize_with(count, Ingredients::empty);
            for (pass, first) in passes.iter_mut().zip((0..cols).step_by(DIRECTIONS)) {
                match second {
                    Some(so) => *pass = so.first_order(first, cols),
                    _ => self.first_order_ingredients((x, u), first, seeds, jets, pass)?,
                }
            }
        }
        // The ingredients' values make the step's problem (the geometry runs once).
        match direct {
            Some(ex) => ex.values_into(&mut values.M, &mut values.r, &mut values.cons),
            None => {
                let ing = &passes[0];
                let re = |out: &mut Vec<f64>, v: &[D1]| {
                    out.clear();
                    out.extend(v.iter().map(|e| e.re));
                };
                re(&mut values.M, &ing.M);
                re(&mut values.r, &ing.r);
                re(&mut values.cons.jacobian, &ing.jac);
                values.cons.d.clear();
                values.cons.d.extend_from_slice(&ing.distance);
                values.cons.contacts.clear();
                values.cons.contacts.extend_from_slice(&ing.contacts);
            }
        }
        for (r, f) in values.r.iter_mut().zip(source.forces()) {
            *r += f;
        }
        let cons = &values.cons;
        let lcp = std::mem::take(&mut values.lcp);
        let problem = self.assemble_into(&x[n..], &values.M, &values.r, cons, lcp)?;
        let problem = match source {
            Source::Stored(_) => problem,
            Source::Solve(data) => crate::step::with_solve_scratch(|scratch| {
                self.solve_into(data, scratch, (x, u), problem, cons)
            })?,
        };
        let step = source
            .step()
            .expect("a stored step (checked by the entry point) or one just solved");
        if step.info.status != ncp::Status::Converged {
            return Err(DynamicsError::Unsupported(
                "derivatives of a step whose complementarity solve did not converge",
            ));
        }
        let m = step.lambda.len();
        let h = self.settings().h;
        let Values { z, f, jac, .. } = values;
        z.clear();
        z.extend_from_slice(&step.x_next[n..]);
        z.extend_from_slice(&step.lambda);
        let dim = n + m;
        for (buffer, len) in [(&mut *f, dim), (&mut *jac, dim * dim)] {
            buffer.clear();
            buffer.resize(len, 0.0);
        }
        problem.evaluate(z, f, Some(jac));
        values.lcp = problem.into_row_major();
        let normal = matches!(model, Complementarity::Normal { .. });
        let Linearised {
            p,
            lu,
            dp,
            kinds,
            dcorrection,
        } = lin;
        if normal {
            (*p, _, *lu, *kinds, values.slope) = self.normal_system(z, f, jac, n)?;
        } else {
            self.complementarity_system(n, (p, kinds), values, lu)?;
        }
        let slope = &values.slope;
        let np = p.len();
        dp.clear();
        dp.resize(np * cols, 0.0);
        // The position-level correction's derivatives: a function of q alone.
        dcorrection.clear();
        dcorrection.resize(n * cols, 0.0);
        match direct {
            Some(ex) => {
                ex.equations_y(h, &x[n..], p, slope, dp);
                let geo = &ex.geometry;
                for i in 0..n {
                    dcorrection[i * cols..i * cols + n].copy_from_slice(geo.g(ex.correction(i)));
                }
            }
            None => {
                // The equations' derivatives in y = (x, u) in duals, eight directions per pass (one
                // pass for the finger), and the correction's read off its duals.
                let Duals { pc, v, res, w } = duals;
                pc.clear();
                pc.extend(p.iter().map(|&e| D1::from_re(e)));
                for (ing, first) in passes.iter().zip((0..cols).step_by(DIRECTIONS)) {
                    v.clear();
                    v.extend((0..n).map(|j| {
                        let d = D1::from_re(x[n + j]);
                        if (first..first + DIRECTIONS).contains(&(n + j)) {
                            d.derivative(n + j - first)
                        } else {
                            d
                        }
                    }));
                    system_into(n, h, ing, (v, pc), kinds, normal, (res, w));
                    for k in 0..DIRECTIONS.min(cols - first) {
                        for (i, e) in res.iter().enumerate() {
                            dp[i * cols + first + k] = -e.eps.0.as_ref().map_or(0.0, |g| g[k]);
                        }
                    }
                    for (i, e) in ing.correction.iter().enumerate() {
                        if let Some(g) = e.eps.0.as_ref() {
                            for k in 0..DIRECTIONS.min(cols - first) {
                                dcorrection[i * cols + first + k] = g[k];
                            }
                        }
                    }
                }
            }
        }
        lu.solve_many(dp, cols);
        Ok(())
    }

    /// Logistic and hard models: `p = z`, the Newton matrix with each row's `(d phi/d lambda, d phi/d w)`
    /// (in `values.H`; `values.z`, `f` and `jac` are the solution, the residual and its Jacobian);
    /// redundant active rows held fixed. `p` and the rows' kinds into `p` and `kinds`, each row's slope in
    /// `w` into `values.slope`, the factors into `lu` (a new workspace when it has another size).
    fn complementarity_system(
        &self,
        n: usize,
        (p, kinds): (&mut Vec<f64>, &mut Vec<RowKind>),
        values: &mut Values,
        lu: &mut DenseLu,
    ) -> Result<(), DynamicsError> {
        let Values {
            z,
            f,
            jac,
            H,
            dphi,
            slope,
            ..
        } = values;
        let dim = z.len();
        let m = dim - n;
        let model = self.settings().model;
        let sigmas: Option<Vec<f64>> = self.state_covariance().map(|_| {
            let rows: Vec<f64> = (0..m)
                .flat_map(|k| jac[(n + k) * dim..(n + k) * dim + n].iter().copied())
                .collect();
            self.noise(&rows, m)
        });
        kinds.clear();
        dphi.clear();
        dphi.resize(m, (0.0, 0.0));
        for k in 0..m {
            let (lambda, w) = (z[n + k], f[n + k]);
            let (kind, d) = match model {
                Complementarity::Logistic { sigma } => {
                    // A constant noise reads no Jacobian.
                    let sigma = sigmas.as_ref().map_or(sigma, |s| s[k]);
                    let (_, da, db) = NcpFunction::Logistic { sigma }.first_order(lambda, w);
                    (RowKind::Logistic, (da, db))
                }
                _ if lambda > 0.0 => (RowKind::Contact, (0.0, 1.0)),
                _ => (RowKind::Fixed, (1.0, 0.0)),
            };
            kinds.push(kind);
            dphi[k] = d;
        }
        let build = |H: &mut Vec<f64>, dphi: &[(f64, f64)]| {
            H.clear();
            H.extend_from_slice(jac);
            for k in 0..m {
                let row = &mut H[(n + k) * dim..(n + k + 1) * dim];
                for e in row.iter_mut() {
                    *e *= dphi[k].1;
                }
                row[n + k] += dphi[k].0;
            }
        };
        build(H, dphi);
        if lu.dim() != dim {
            *lu = DenseLu::new(dim, LinearSolver::Hand);
        }
        // Redundant active rows (more than the velocities can satisfy independently) make the matrix
        // singular: exactly for the hard model's active set, to working precision for a smoothed row whose
        // d phi / d lambda has underflowed (lambda >> sigma). The velocities are still unique. Hold the
        // smallest impulses of such rows fixed, one at a time, until the remaining active rows are
        // independent: the derivative of that branch of impulses, and the derivative of v'.
        while let Err(cause) = lu.factor(H) {
            let weakest = (0..m)
                .filter(|&k| dphi[k].1 > 0.5 && dphi[k].0 < 1e-12)
                .min_by(|&a, &b| z[n + a].total_cmp(&z[n + b]));
            match weakest {
                Some(k) => {
                    dphi[k] = (1.0, 0.0);
                    kinds[k] = RowKind::Fixed;
                    build(H, dphi);
                }
                None => {
                    return Err(DynamicsError::Singular {
                        what: "the step's Jacobian",
                        cause,
                    });
                }
            }
        }
        slope.clear();
        slope.extend(dphi.iter().map(|d| d.1));
        p.clear();
        p.extend_from_slice(z);
        Ok(())
    }

    /// Normal model: `p = [v'; lambda; nu]` with `nu = -M^-1 J^T e_b` and the first-order conditions'
    /// Jacobian; rows with `lambda_i = 0` are on their bound and held there.
    fn normal_system(
        &self,
        z: &[f64],
        f: &[f64],
        jac: &[f64],
        n: usize,
    ) -> Result<System, DynamicsError> {
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
        lu.factor(&mass).map_err(|cause| DynamicsError::Singular {
            what: "the mass matrix",
            cause,
        })?;
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
        lu.factor(&H).map_err(|cause| DynamicsError::Singular {
            what: "the step's Jacobian",
            cause,
        })?;
        Ok((p, H, lu, kinds, Vec::new()))
    }
}

impl Model {
    /// The step's first derivatives (into `diff.first`) and what its second derivatives keep besides
    /// them (into `diff.parts`), for the step in `source` (solved now or stored), refilled in place.
    pub(super) fn second_order_parts(
        &self,
        x: &[f64],
        u: &[f64],
        mut source: Source<'_>,
        diff: &mut DerivativeData,
    ) -> Result<(), DynamicsError> {
        let (n, nu, h) = (
            self.scene().n_dof(),
            self.scene().n_controls,
            self.settings().h,
        );
        let cols = 2 * n + nu;
        let bytes = self.second_order_bytes();
        if bytes > super::SECOND_ORDER_MAX_BYTES {
            return Err(DynamicsError::TooLarge {
                what: "one step's second-order expansion",
                bytes,
                limit: super::SECOND_ORDER_MAX_BYTES,
                alternative: "first derivatives only: iLQR / Gauss-Newton (--method ilqr)",
            });
        }
        let DerivativeData { first, parts, .. } = diff;
        // A stored step computed its contacts at this `x`: the expansion finishes from them.
        let step = match &source {
            Source::Stored(stored) => Some(stored.step),
            Source::Solve(_) => None,
        };
        let seeds = step.map(|s| s.contacts.as_slice());
        with_work(|work| {
            self.expansion((x, u), seeds, &mut parts.expansion, &mut work.jets)?;
            let ing = &parts.expansion;
            self.linearise(x, u, Some(ing), &mut source, &mut parts.lin, work)
        })?;
        let ing = &parts.expansion;
        self.first_derivatives_into(&parts.lin, first);
        let model = self.settings().model;
        (parts.n, parts.cols, parts.h) = (n, cols, h);
        match model {
            Complementarity::Hard => {
                parts.equations = Equations::Structured;
                parts.structured.fill(ing, (h, 0.0), x, &parts.lin);
            }
            Complementarity::Logistic { sigma } if !self.has_state_covariance() => {
                parts.equations = Equations::Structured;
                parts.structured.fill(ing, (h, sigma), x, &parts.lin);
            }
            _ => {
                let normal = matches!(model, Complementarity::Normal { .. });
                parts.equations = Equations::Assembled;
                general_hessians(ing, (h, x), &parts.lin, cols, normal, &mut parts.assembled);
            }
        }
        correction_hessians(ing, &mut parts.correction);
        Ok(())
    }

    /// [`Model::second_order_parts`] with a copy of the step, as one owned value.
    pub(super) fn second_order_from(
        &self,
        x: &[f64],
        u: &[f64],
        source: Source<'_>,
    ) -> Result<SecondOrderStep, DynamicsError> {
        let mut diff = DerivativeData::default();
        let step = match source {
            Source::Solve(data) => {
                self.second_order_parts(x, u, Source::Solve(&mut *data), &mut diff)?;
                data.step().expect("linearised above").clone()
            }
            Source::Stored(stored) => {
                self.second_order_parts(x, u, Source::Stored(stored), &mut diff)?;
                stored.step.clone()
            }
        };
        Ok(SecondOrderStep {
            step,
            derivatives: diff.first,
            parts: std::cell::RefCell::new(diff.parts),
        })
    }
}

/// A step prepared for its second derivatives ([`Simulator::second_order_step`]): the step, its first
/// derivatives, and the Hessian of `c^T f` for any `c` by [`SecondOrderStep::hessian`]. Second-order
/// adjoint: with `K_p^T mu = -g` for the step's equations `K(p; y) = 0` and `g = (dx'/dp)^T c`,
/// `d^2 (c^T f) / dy^2 = T^T (d^2 (mu^T K) / d(p, y)^2) T`, `T = [dp/dy; I]`, the inner Hessian along the
/// columns of `T` (stage 3, module documentation). An owned copy of what [`Model::calc_diff2_prepare`]
/// keeps in a step's data.
pub struct SecondOrderStep {
    /// The step.
    pub step: Step,
    /// Its first derivatives.
    pub derivatives: StepDerivatives,
    parts: std::cell::RefCell<SecondOrderParts>,
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
        let cols = self.parts.borrow().cols;
        let mut hess = vec![0.0; cols * cols];
        self.hessian_into(c, &mut hess)?;
        Ok(hess)
    }

    /// [`SecondOrderStep::hessian`] written into `hess` (`(2n + n_u)^2` entries), which is overwritten.
    pub fn hessian_into(&self, c: &[f64], hess: &mut [f64]) -> Result<(), DynamicsError> {
        self.parts.borrow_mut().hessian_into(c, hess)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Scene, Simulator, StepSettings};

    /// SCENE.md's flicking finger, from its scene file.
    fn finger_scene() -> Scene {
        Scene::from_toml_str(include_str!("../../../../scenes/finger.toml")).unwrap()
    }

    /// The expansion finished from the step's own contacts (a stored step's seeds) is the one a fresh
    /// search gives, to the bit: on the finger, two fingers and the three-link finger (one, two and
    /// three pairs of ellipses), along rollouts that touch, apart and in contact.
    #[test]
    fn the_expansion_from_the_steps_contacts_is_the_searched_one_to_the_bit() {
        for text in [
            include_str!("../../../../scenes/finger.toml"),
            include_str!("../../../../scenes/two_fingers.toml"),
            include_str!("../../../../scenes/three_link_finger.toml"),
        ] {
            let scene = Scene::from_toml_str(text).unwrap();
            let (n, nu) = (scene.n_dof(), scene.n_controls);
            let mut sim = Simulator::new(scene, StepSettings::default()).unwrap();
            let mut x = vec![0.0; 2 * n];
            let (mut jets, mut seeded, mut searched) =
                (Vec::new(), Expansion::default(), Expansion::default());
            let mut compared = 0;
            for t in 0..40 {
                let u: Vec<f64> = (0..nu)
                    .map(|j| 2.0 * ((t * (j + 3)) as f64 * 0.37).sin())
                    .collect();
                let step = sim.step(&x, &u).unwrap();
                let contacts = &sim.data().step().unwrap().contacts;
                assert!(contacts.iter().any(|c| c.seed.is_some()));
                sim.model()
                    .expansion((&x, &u), Some(contacts), &mut seeded, &mut jets)
                    .unwrap();
                sim.model()
                    .expansion((&x, &u), None, &mut searched, &mut jets)
                    .unwrap();
                assert_eq!(seeded.geometry.bits(), searched.geometry.bits(), "step {t}");
                assert_eq!(seeded.forces.bits(), searched.forces.bits(), "step {t}");
                assert_eq!(seeded.contacts, searched.contacts, "step {t}");
                // The first-order duals' ingredients (iLQR's path) as well.
                let (mut a, mut b) = (Ingredients::empty(), Ingredients::empty());
                let model = sim.model();
                model
                    .first_order_ingredients((&x, &u), 0, Some(contacts), &mut jets, &mut a)
                    .unwrap();
                model
                    .first_order_ingredients((&x, &u), 0, None, &mut jets, &mut b)
                    .unwrap();
                let show = |i: &Ingredients<D1>| {
                    format!(
                        "{:?}",
                        (
                            &i.M,
                            &i.r,
                            &i.jac,
                            &i.d,
                            &i.sigma,
                            &i.correction,
                            &i.contacts
                        )
                    )
                };
                assert_eq!(show(&a), show(&b), "step {t}");
                compared += 1;
                x = step.x_next;
            }
            assert_eq!(compared, 40);
        }
    }

    /// The structured equation Hessians and the dual path (one pass, or one per pair of blocks of four
    /// directions) for the same step and `c`.
    fn both(sim: &mut Simulator, x: &[f64], u: &[f64], c: &[f64]) -> (Vec<f64>, Vec<f64>, f64) {
        let structured = sim.second_order_step(x, u).unwrap();
        // The same step's parts again, its equations' Hessians assembled in duals.
        let model = sim.model();
        let mut diff = DerivativeData::default();
        let stored = sim.data().stored().unwrap();
        model
            .second_order_parts(x, u, Source::Stored(stored), &mut diff)
            .unwrap();
        let mut parts = diff.parts;
        let cols = parts.cols;
        general_hessians(
            &parts.expansion,
            (parts.h, x),
            &parts.lin,
            cols,
            false,
            &mut parts.assembled,
        );
        parts.equations = Equations::Assembled;
        let step = stored.step.clone();
        let lambda = step.lambda.iter().fold(0.0f64, |a, &b| a.max(b));
        let general = SecondOrderStep {
            step,
            derivatives: structured.derivatives.clone(),
            parts: std::cell::RefCell::new(parts),
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

    /// The forces' expansion tree by tree ([`Model::expansion`] on a scene of several trees) against the
    /// whole scene's forces in one jet (block pairs of three directions): the same numbers to the last
    /// bit, the entries between trees zero.
    fn forces_by_tree_are_the_whole_ones(scene: Scene, states: &[Vec<f64>], u: &[f64]) {
        let n = scene.n_dof();
        let m = scene.n_constraints();
        assert!(scene.trees().len() > 1);
        let sim = Simulator::new(scene, StepSettings::default()).unwrap();
        let model = sim.model();
        let mut jets = Vec::new();
        let mut by_tree = Expansion::default();
        let mut whole = Taylor::default();
        for x in states {
            model
                .expansion((x, u), None, &mut by_tree, &mut jets)
                .unwrap();
            let JetWork { args, ing } = jet_work::<Jet<6, 21>>(&mut jets, (n, m));
            Taylor::expand::<6, 21>(&mut whole, &x[..2 * n], n, args, |qv, sink| {
                model.forces(qv, u, None, ing);
                sink.emit(&ing.r);
                Ok(())
            })
            .unwrap();
            let tree = |j: usize| {
                let trees = model.scene().trees();
                (0..trees.len())
                    .find(|&t| trees[t].coordinates.contains(&(j % n)))
                    .unwrap()
            };
            let ours = &by_tree.forces;
            for i in 0..n {
                assert_eq!(
                    ours.re(i).to_bits(),
                    whole.re(i).to_bits(),
                    "r[{i}] at {x:?}"
                );
                for a in 0..2 * n {
                    let same = tree(a) == tree(i);
                    let g = ours.g(i)[a];
                    assert!(same || g == 0.0, "dr[{i}]/dy[{a}] = {g} across trees");
                    assert_eq!(g, whole.g(i)[a], "dr[{i}]/dy[{a}] at {x:?}");
                    for b in 0..2 * n {
                        let h = ours.hessian(i, a, b);
                        assert!(
                            (same && tree(b) == tree(i)) || h == 0.0,
                            "d2r[{i}]/dy[{a}]dy[{b}] = {h} across trees"
                        );
                        assert_eq!(h, whole.hessian(i, a, b), "d2r[{i}] at {x:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn each_trees_forces_are_expanded_alone_and_are_the_whole_scenes() {
        let states = |n: usize| -> Vec<Vec<f64>> {
            (0..5)
                .map(|k| {
                    (0..2 * n)
                        .map(|i| ((i * 5 + k * 3) % 7) as f64 * 0.4 - 1.1)
                        .collect()
                })
                .collect()
        };
        // The finger (a two-link tree and the ellipse), two fingers (three trees), pushing (a free block:
        // two slides and an angle).
        for (text, u) in [
            (
                include_str!("../../../../scenes/finger.toml"),
                vec![0.3, -0.2],
            ),
            (
                include_str!("../../../../scenes/two_fingers.toml"),
                vec![0.2, -0.3, 0.1, 0.4],
            ),
            (
                include_str!("../../../../scenes/pushing.toml"),
                vec![0.5, -0.5],
            ),
        ] {
            let scene = Scene::from_toml_str(text).unwrap();
            let n = scene.n_dof();
            forces_by_tree_are_the_whole_ones(scene, &states(n), &u);
        }
        // A tree of seven links (14 directions: passes over pairs of its blocks) beside the ellipse.
        let mut spec = finger_scene().spec().clone();
        for k in 3..=7 {
            let mut link = spec.bodies[1].clone();
            link.name = format!("link{k}");
            link.parent = format!("link{}", k - 1);
            link.semi_axes = [0.3, 0.1];
            link.centre = [0.3, 0.0];
            link.joint.limits = None;
            link.joint.damping = 0.002 * k as f64;
            spec.bodies.insert(k - 1, link);
        }
        let scene = Scene::new(spec).unwrap();
        assert_eq!(scene.trees()[0].coordinates.len(), 7);
        let u: Vec<f64> = (0..scene.n_controls)
            .map(|k| 0.1 * k as f64 - 0.2)
            .collect();
        forces_by_tree_are_the_whole_ones(scene, &states(8), &u);
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
            let mut sim = Simulator::new(finger_scene(), settings).unwrap();
            assert!(
                agree(&mut sim, &finger, &[0.3, -0.2]) > 0,
                "{model:?}: no contact"
            );
        }
        // A third link: 4 joints, 3 controls, 11 directions (six pairs of blocks in duals).
        let mut spec = finger_scene().spec().clone();
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
