//! Positions, Jacobians, the mass matrix `M(q)` and the bias forces `r(q, v)` (gravity, joint drag,
//! Coriolis and centripetal) of a scene (SCENE.md "Inertia, forces"), by the usual rigid-body equations.
//!
//! A coordinate either turns its body about the origin of the body's joint frame (a hinge, or a free
//! joint's angle) or slides the frame along an axis of the parent's frame (a slider, or a free joint's x
//! and y). The velocity a turning coordinate `j` gives a point `p` of a body it moves is `v_j perp(p - o_j)`,
//! with `o_j` its body's frame origin (a hinge's pivot) and `perp(x) = (-x_y, x_x)`; a sliding one gives
//! `v_j a_j`, its axis in the world. Point Jacobians, the Jacobians of the centres (for `M`) and of the
//! witness points (for the contact rows) all come from that.
//!
//! Generic over the scalar (`f64` for the step, forward-mode dual numbers for its exact derivatives): this
//! is the one place the step's ingredients are written, so the derivatives differentiate the same code.

#![allow(non_snake_case)]

use crate::scene::{CoordinateKind, Scene};
use num_dual::DualNum;

/// The scalars the step's equations run on: `f64` and `num-dual`'s forward-mode types over `f64` (the
/// contact geometry needs `DualNum`).
pub trait Scalar: DualNum<Primitive = f64> + Copy {}
impl<T: DualNum<Primitive = f64> + Copy> Scalar for T {}

/// The arithmetic the kinematics, the mass matrix, the forces and the contact geometry need (geometry's
/// [`Forward`](geometry::Forward)): every [`Scalar`], and the crate's fused second-order [`Jet`](crate::Jet).
pub use geometry::Forward as Ring;

/// `(-x_y, x_x)`.
#[inline]
pub fn perp<T: Ring>(x: [T; 2]) -> [T; 2] {
    [-x[1], x[0]]
}

/// `x` turned by the angle whose `(sin, cos)` is `turn`.
#[inline]
fn rotate<T: Ring>((s, c): (T, T), x: [f64; 2]) -> [T; 2] {
    [c * x[0] - s * x[1], s * x[0] + c * x[1]]
}

#[inline]
fn add<T: Ring>(a: [T; 2], b: [T; 2]) -> [T; 2] {
    [a[0] + b[0], a[1] + b[1]]
}

#[inline]
fn sub<T: Ring>(a: [T; 2], b: [T; 2]) -> [T; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

/// Absolute angles, frame origins and centres of every body at `q`, and the sliding coordinates' axes.
#[derive(Debug, Clone, PartialEq)]
pub struct Kinematics<T = f64> {
    /// Absolute angle of each body's joint frame.
    pub phi: Vec<T>,
    /// `(sin, cos)` of each body's `phi`, computed once for every rotation by it.
    pub turn: Vec<(T, T)>,
    /// Origin of each body's joint frame (a hinge's pivot).
    pub hinge: Vec<[T; 2]>,
    /// Centre of each body's ellipse.
    pub centre: Vec<[T; 2]>,
    /// Each coordinate's axis in the world frame if it slides (empty when no coordinate does).
    pub axis: Vec<[T; 2]>,
}

impl<T: Ring> Kinematics<T> {
    /// Forward kinematics (parents come before children in a scene).
    pub fn new(scene: &Scene, q: &[T]) -> Self {
        let mut kin = Kinematics {
            phi: Vec::new(),
            turn: Vec::new(),
            hinge: Vec::new(),
            centre: Vec::new(),
            axis: Vec::new(),
        };
        kin.update(scene, q);
        kin
    }

    /// The kinematics in `slot` updated to `q` ([`Kinematics::update`]), or new ones made there: the
    /// kinematics a step's or a derivative pass's working vectors keep from one call to the next.
    pub fn refresh<'a>(slot: &'a mut Option<Self>, scene: &Scene, q: &[T]) -> &'a mut Self {
        match slot {
            Some(kin) => {
                kin.update(scene, q);
                kin
            }
            None => slot.insert(Kinematics::new(scene, q)),
        }
    }

    /// [`Kinematics::new`] in place: the same vectors refilled, without allocating once they have the
    /// scene's sizes (a step's data keeps one).
    pub fn update(&mut self, scene: &Scene, q: &[T]) {
        let nb = scene.bodies.len();
        let zero = T::from(0.0);
        let Kinematics {
            phi,
            turn,
            hinge,
            centre,
            axis,
        } = self;
        phi.clear();
        phi.resize(nb, zero);
        turn.clear();
        turn.resize(nb, (zero, zero));
        hinge.clear();
        hinge.resize(nb, [zero; 2]);
        centre.clear();
        centre.resize(nb, [zero; 2]);
        let slides = scene
            .coordinates
            .iter()
            .any(|c| matches!(c.kind, CoordinateKind::Slide { .. }));
        axis.clear();
        if slides {
            axis.resize(scene.n_dof(), [zero; 2]);
        }
        for (i, b) in scene.bodies.iter().enumerate() {
            // The parent's frame (the world's for a root body), then the joint's coordinates in order:
            // slides move the origin along their axes, an angle turns the frame.
            let (mut angle, mut origin) = match b.parent {
                None => (None, [T::from(b.anchor[0]), T::from(b.anchor[1])]),
                Some(p) => (Some(phi[p]), add(hinge[p], rotate(turn[p], b.anchor))),
            };
            for c in b.coordinates.clone() {
                match scene.coordinates[c].kind {
                    CoordinateKind::Slide { axis: a } => {
                        let world = match b.parent {
                            None => [T::from(a[0]), T::from(a[1])],
                            Some(p) => rotate(turn[p], a),
                        };
                        origin = add(origin, [world[0] * q[c], world[1] * q[c]]);
                        axis[c] = world;
                    }
                    CoordinateKind::Angle => {
                        angle = Some(angle.map_or(q[c], |a| a + q[c]));
                    }
                }
            }
            phi[i] = angle.unwrap_or(zero);
            turn[i] = phi[i].sin_and_cos();
            hinge[i] = origin;
            centre[i] = add(hinge[i], rotate(turn[i], b.centre));
        }
    }

    /// Jacobian (rows `[dx/dq; dy/dq]`, each of length n) of the material point of `body` at world
    /// position `p`.
    pub fn point_jacobian(&self, scene: &Scene, body: usize, p: [T; 2]) -> [Vec<T>; 2] {
        let n = scene.n_dof();
        let zero = T::from(0.0);
        let mut jac = [vec![zero; n], vec![zero; n]];
        for j in 0..n {
            [jac[0][j], jac[1][j]] = self.point_jacobian_column(scene, body, p, j);
        }
        jac
    }

    /// Column `j` of [`Kinematics::point_jacobian`]: the velocity of that point per unit velocity of joint
    /// `j` (zero when the joint does not move `body`).
    #[inline]
    pub fn point_jacobian_column(&self, scene: &Scene, body: usize, p: [T; 2], j: usize) -> [T; 2] {
        self.lever(scene, j, body, p).unwrap_or([T::from(0.0); 2])
    }

    /// The generalised forces (one per joint, `J_p^T F`) of the world force `force` acting on the material
    /// point of `body` at world position `p`.
    pub fn point_force(&self, scene: &Scene, body: usize, p: [T; 2], force: [T; 2]) -> Vec<T> {
        let [jx, jy] = self.point_jacobian(scene, body, p);
        jx.iter()
            .zip(&jy)
            .map(|(&a, &b)| a * force[0] + b * force[1])
            .collect()
    }

    /// Velocity of the material point of `body` at `p` for joint velocities `v`.
    pub fn point_velocity(&self, scene: &Scene, body: usize, p: [T; 2], v: &[T]) -> [T; 2] {
        let mut out = [T::from(0.0); 2];
        for (j, vj) in v.iter().enumerate() {
            if let Some(c) = self.lever(scene, j, body, p) {
                out[0] += *vj * c[0];
                out[1] += *vj * c[1];
            }
        }
        out
    }

    /// The mass matrix `M(q) = sum_i m_i Jc_i^T Jc_i + I_i Jw_i^T Jw_i` (row-major `n x n`; `Jw` is one for
    /// the turning coordinates that move body `i`, zero for the sliding ones).
    pub fn mass_matrix(&self, scene: &Scene) -> Vec<T> {
        let mut M = Vec::new();
        self.mass_matrix_into(scene, &mut M);
        M
    }

    /// [`Kinematics::mass_matrix`] into `M` (resized to `n x n`; no allocation once it has that size).
    pub fn mass_matrix_into(&self, scene: &Scene, M: &mut Vec<T>) {
        let n = scene.n_dof();
        M.clear();
        M.resize(n * n, T::from(0.0));
        for (i, b) in scene.bodies.iter().enumerate() {
            for r in 0..n {
                let Some(lr) = self.lever(scene, r, i, self.centre[i]) else {
                    continue;
                };
                for c in r..n {
                    let Some(lc) = self.lever(scene, c, i, self.centre[i]) else {
                        continue;
                    };
                    let turning = |k: usize| scene.coordinates[k].kind == CoordinateKind::Angle;
                    let inertia = if turning(r) && turning(c) {
                        b.inertia
                    } else {
                        0.0
                    };
                    M[r * n + c] += (lr[0] * lc[0] + lr[1] * lc[1]) * b.mass + inertia;
                }
            }
        }
        for r in 0..n {
            for c in 0..r {
                M[r * n + c] = M[c * n + r];
            }
        }
    }

    /// Column `j` of the Jacobian of the material point of `body` at `p`, if coordinate `j` moves the body:
    /// `perp(p - o)` for a turning coordinate (`o` its body's frame origin), its world axis for a sliding
    /// one.
    #[inline(always)]
    pub fn lever(&self, scene: &Scene, j: usize, body: usize, p: [T; 2]) -> Option<[T; 2]> {
        if !scene.moves(j, body) {
            return None;
        }
        let c = &scene.coordinates[j];
        Some(match c.kind {
            CoordinateKind::Angle => perp(sub(p, self.hinge[c.body])),
            CoordinateKind::Slide { .. } => self.axis[j],
        })
    }

    /// The generalised forces of a step: `r(q, v) + B u`, the controls acting on their actuated joints.
    pub fn applied_forces(&self, scene: &Scene, v: &[T], u: &[T]) -> Vec<T> {
        let mut r = Vec::new();
        self.applied_forces_into(scene, v, u, &mut r, &mut ForceScratch::default());
        r
    }

    /// [`Kinematics::applied_forces`] into `r`, with the bias forces' per-body velocities in `scratch`
    /// (no allocation once both have the scene's sizes).
    pub fn applied_forces_into(
        &self,
        scene: &Scene,
        v: &[T],
        u: &[T],
        r: &mut Vec<T>,
        scratch: &mut ForceScratch<T>,
    ) {
        self.applied_forces_of(scene, None, (v, u), r, scratch);
    }

    /// Bias forces `r(q, v)`: gravity on every centre, `-damping * v` on every coordinate, and the Coriolis
    /// and centripetal forces `-sum_i m_i Jc_i^T (dJc_i/dt v)`, with `dJc_i/dt v = sum_j v_j dJ_j/dt`:
    /// `perp(dc_i/dt - do_j/dt)` for a turning coordinate `j` (`o_j` its body's frame origin),
    /// `omega perp(a_j)` for a sliding one (`omega` the angular velocity of its body's parent). In the plane
    /// the rotational inertia adds no velocity term.
    pub fn bias_forces(&self, scene: &Scene, v: &[T]) -> Vec<T> {
        let mut r = Vec::new();
        self.bias_forces_into(scene, v, &mut r, &mut ForceScratch::default());
        r
    }

    /// [`Kinematics::bias_forces`] into `r` (see [`Kinematics::applied_forces_into`]).
    pub fn bias_forces_into(
        &self,
        scene: &Scene,
        v: &[T],
        r: &mut Vec<T>,
        scratch: &mut ForceScratch<T>,
    ) {
        self.bias_forces_of(scene, None, v, r, scratch);
    }

    /// [`Kinematics::applied_forces_into`] for the coordinates of one kinematic tree
    /// ([`Scene::trees`]): the entries of `r` for the tree's coordinates are the applied forces, computed
    /// from its own bodies alone (the same arithmetic in the same order as for the whole scene); the other
    /// entries hold their drag and controls only. What the second derivatives of the forces need, one tree
    /// at a time, in jets over that tree's coordinates alone.
    pub fn tree_forces_into(
        &self,
        scene: &Scene,
        tree: usize,
        (v, u): (&[T], &[T]),
        r: &mut Vec<T>,
        scratch: &mut ForceScratch<T>,
    ) {
        let bodies = &scene.trees()[tree].bodies;
        self.applied_forces_of(scene, Some(bodies), (v, u), r, scratch);
    }

    /// The bias forces from `bodies` ([`Kinematics::bias_forces_of`]) plus the controls.
    fn applied_forces_of(
        &self,
        scene: &Scene,
        bodies: Option<&[usize]>,
        (v, u): (&[T], &[T]),
        r: &mut Vec<T>,
        scratch: &mut ForceScratch<T>,
    ) {
        self.bias_forces_of(scene, bodies, v, r, scratch);
        for (j, c) in scene.coordinates.iter().enumerate() {
            if let Some(k) = c.actuator {
                r[j] += u[k];
            }
        }
    }

    /// The bias forces from the bodies `bodies` (all of them for `None`; a tree's, or its velocities'
    /// terms would be missing).
    fn bias_forces_of(
        &self,
        scene: &Scene,
        bodies: Option<&[usize]>,
        v: &[T],
        r: &mut Vec<T>,
        scratch: &mut ForceScratch<T>,
    ) {
        let n = scene.n_dof();
        let counted = |i: usize| bodies.is_none_or(|b| b.contains(&i));
        let zero = T::from(0.0);
        r.clear();
        r.extend(
            scene
                .coordinates
                .iter()
                .zip(v)
                .map(|(c, vj)| *vj * (-c.damping)),
        );
        // Frame origins' velocities: the origin of body j is a point of j's parent, moved along the
        // joint's own sliding axes.
        let ForceScratch {
            origin_velocity,
            omega,
        } = scratch;
        origin_velocity.clear();
        origin_velocity.extend(scene.bodies.iter().enumerate().map(|(j, b)| {
            if !counted(j) {
                return [zero; 2];
            }
            let mut w = match b.parent {
                None => [zero; 2],
                Some(p) => self.point_velocity(scene, p, self.hinge[j], v),
            };
            for c in b.coordinates.clone() {
                if let CoordinateKind::Slide { .. } = scene.coordinates[c].kind {
                    w[0] += v[c] * self.axis[c][0];
                    w[1] += v[c] * self.axis[c][1];
                }
            }
            w
        }));
        // Each body's angular velocity (needed by sliding coordinates only).
        omega.clear();
        if !self.axis.is_empty() {
            for (i, b) in scene.bodies.iter().enumerate() {
                if !counted(i) {
                    omega.push(zero);
                    continue;
                }
                let mut w = b.parent.map_or(zero, |p| omega[p]);
                for c in b.coordinates.clone() {
                    if scene.coordinates[c].kind == CoordinateKind::Angle {
                        w += v[c];
                    }
                }
                omega.push(w);
            }
        }
        for (i, b) in scene.bodies.iter().enumerate() {
            if !counted(i) {
                continue;
            }
            let cdot = self.point_velocity(scene, i, self.centre[i], v);
            let mut accel = [T::from(0.0); 2];
            for j in 0..n {
                if scene.moves(j, i) {
                    let c = &scene.coordinates[j];
                    let w = match c.kind {
                        CoordinateKind::Angle => perp(sub(cdot, origin_velocity[c.body])),
                        CoordinateKind::Slide { .. } => {
                            let turn = scene.bodies[c.body].parent.map_or(zero, |p| omega[p]);
                            let a = perp(self.axis[j]);
                            [a[0] * turn, a[1] * turn]
                        }
                    };
                    accel[0] += v[j] * w[0];
                    accel[1] += v[j] * w[1];
                }
            }
            let f = [
                (-accel[0] + scene.gravity[0]) * b.mass,
                (-accel[1] + scene.gravity[1]) * b.mass,
            ];
            for k in 0..n {
                if let Some(l) = self.lever(scene, k, i, self.centre[i]) {
                    r[k] += l[0] * f[0] + l[1] * f[1];
                }
            }
        }
    }
}

/// The per-body velocities [`Kinematics::bias_forces_into`] works in, kept between calls so that it does
/// not allocate.
#[derive(Debug, Clone)]
pub struct ForceScratch<T = f64> {
    origin_velocity: Vec<[T; 2]>,
    omega: Vec<T>,
}

impl<T> Default for ForceScratch<T> {
    fn default() -> Self {
        ForceScratch {
            origin_velocity: Vec::new(),
            omega: Vec::new(),
        }
    }
}
