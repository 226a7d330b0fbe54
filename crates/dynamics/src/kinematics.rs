//! Positions, Jacobians, the mass matrix `M(q)` and the bias forces `r(q, v)` (gravity, joint drag,
//! Coriolis and centripetal) of a scene (SCENE.md "Inertia, forces"), by the usual rigid-body equations.
//!
//! Every joint is a hinge, so the velocity that joint `j` gives a point `p` of a body it moves is
//! `v_j perp(p - h_j)`, with `h_j` the joint's hinge and `perp(x) = (-x_y, x_x)`. Point Jacobians, the
//! Jacobians of the centres (for `M`) and of the witness points (for the contact rows) all come from that.
//!
//! Generic over the scalar (`f64` for the step, forward-mode dual numbers for its exact derivatives): this
//! is the one place the step's ingredients are written, so the derivatives differentiate the same code.

#![allow(non_snake_case)]

use crate::scene::Scene;
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

#[inline]
fn rotate<T: Ring>(phi: T, x: [f64; 2]) -> [T; 2] {
    let (s, c) = phi.sin_and_cos();
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

/// Absolute angles, hinge positions and centres of every body at `q`.
#[derive(Debug, Clone, PartialEq)]
pub struct Kinematics<T = f64> {
    /// Absolute angle of each body's joint frame.
    pub phi: Vec<T>,
    /// Hinge position of each body.
    pub hinge: Vec<[T; 2]>,
    /// Centre of each body's ellipse.
    pub centre: Vec<[T; 2]>,
}

impl<T: Ring> Kinematics<T> {
    /// Forward kinematics (parents come before children in a scene).
    pub fn new(scene: &Scene, q: &[T]) -> Self {
        let n = scene.n_dof();
        let zero = T::from(0.0);
        let (mut phi, mut hinge, mut centre) =
            (vec![zero; n], vec![[zero; 2]; n], vec![[zero; 2]; n]);
        for (i, b) in scene.bodies.iter().enumerate() {
            match b.parent {
                None => {
                    phi[i] = q[i];
                    hinge[i] = [T::from(b.anchor[0]), T::from(b.anchor[1])];
                }
                Some(p) => {
                    phi[i] = phi[p] + q[i];
                    hinge[i] = add(hinge[p], rotate(phi[p], b.anchor));
                }
            }
            centre[i] = add(hinge[i], rotate(phi[i], b.centre));
        }
        Kinematics { phi, hinge, centre }
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
    pub fn point_jacobian_column(&self, scene: &Scene, body: usize, p: [T; 2], j: usize) -> [T; 2] {
        if scene.moves(j, body) {
            perp(sub(p, self.hinge[j]))
        } else {
            [T::from(0.0); 2]
        }
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
            if scene.moves(j, body) {
                let c = perp(sub(p, self.hinge[j]));
                out[0] += *vj * c[0];
                out[1] += *vj * c[1];
            }
        }
        out
    }

    /// The mass matrix `M(q) = sum_i m_i Jc_i^T Jc_i + I_i Jw_i^T Jw_i` (row-major `n x n`).
    pub fn mass_matrix(&self, scene: &Scene) -> Vec<T> {
        let n = scene.n_dof();
        let mut M = vec![T::from(0.0); n * n];
        for (i, b) in scene.bodies.iter().enumerate() {
            for r in 0..n {
                let Some(lr) = self.lever(scene, r, i, self.centre[i]) else {
                    continue;
                };
                for c in r..n {
                    let Some(lc) = self.lever(scene, c, i, self.centre[i]) else {
                        continue;
                    };
                    M[r * n + c] += (lr[0] * lc[0] + lr[1] * lc[1]) * b.mass + b.inertia;
                }
            }
        }
        for r in 0..n {
            for c in 0..r {
                M[r * n + c] = M[c * n + r];
            }
        }
        M
    }

    /// Column `j` of the Jacobian of the material point of `body` at `p`: `perp(p - h_j)` if joint `j`
    /// moves the body, else `None`.
    pub fn lever(&self, scene: &Scene, j: usize, body: usize, p: [T; 2]) -> Option<[T; 2]> {
        scene.moves(j, body).then(|| perp(sub(p, self.hinge[j])))
    }

    /// The generalised forces of a step: `r(q, v) + B u`, the controls acting on their actuated joints.
    pub fn applied_forces(&self, scene: &Scene, v: &[T], u: &[T]) -> Vec<T> {
        let mut r = self.bias_forces(scene, v);
        for (j, b) in scene.bodies.iter().enumerate() {
            if let Some(k) = b.actuator {
                r[j] += u[k];
            }
        }
        r
    }

    /// Bias forces `r(q, v)`: gravity on every centre, `-damping * v` on every joint, and the Coriolis and
    /// centripetal forces `-sum_i m_i Jc_i^T (dJc_i/dt v)`, with `dJc_i/dt v = sum_j v_j perp(dc_i/dt - dh_j/dt)`.
    pub fn bias_forces(&self, scene: &Scene, v: &[T]) -> Vec<T> {
        let n = scene.n_dof();
        let mut r: Vec<T> = scene
            .bodies
            .iter()
            .zip(v)
            .map(|(b, vj)| *vj * (-b.damping))
            .collect();
        // Hinge velocities: the hinge of j is a point of j's parent.
        let hinge_velocity: Vec<[T; 2]> = (0..n)
            .map(|j| match scene.bodies[j].parent {
                None => [T::from(0.0); 2],
                Some(p) => self.point_velocity(scene, p, self.hinge[j], v),
            })
            .collect();
        for (i, b) in scene.bodies.iter().enumerate() {
            let cdot = self.point_velocity(scene, i, self.centre[i], v);
            let mut accel = [T::from(0.0); 2];
            for j in 0..n {
                if scene.moves(j, i) {
                    let w = perp(sub(cdot, hinge_velocity[j]));
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
        r
    }
}
