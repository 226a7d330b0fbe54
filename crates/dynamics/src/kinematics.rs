//! Positions, Jacobians, the mass matrix `M(q)` and the bias forces `r(q, v)` (gravity, joint drag,
//! Coriolis and centripetal) of a scene (SCENE.md "Inertia, forces"), by the usual rigid-body equations.
//!
//! Every joint is a hinge, so the velocity that joint `j` gives a point `p` of a body it moves is
//! `v_j perp(p - h_j)`, with `h_j` the joint's hinge and `perp(x) = (-x_y, x_x)`. Point Jacobians, the
//! Jacobians of the centres (for `M`) and of the witness points (for the contact rows) all come from that.

#![allow(non_snake_case)]

use crate::scene::Scene;

/// `(-x_y, x_x)`.
pub fn perp(x: [f64; 2]) -> [f64; 2] {
    [-x[1], x[0]]
}

fn rotate(phi: f64, x: [f64; 2]) -> [f64; 2] {
    let (s, c) = phi.sin_cos();
    [c * x[0] - s * x[1], s * x[0] + c * x[1]]
}

fn add(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] + b[0], a[1] + b[1]]
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

/// Absolute angles, hinge positions and centres of every body at `q`.
#[derive(Debug, Clone, PartialEq)]
pub struct Kinematics {
    /// Absolute angle of each body's joint frame.
    pub phi: Vec<f64>,
    /// Hinge position of each body.
    pub hinge: Vec<[f64; 2]>,
    /// Centre of each body's ellipse.
    pub centre: Vec<[f64; 2]>,
}

impl Kinematics {
    /// Forward kinematics (parents come before children in a scene).
    pub fn new(scene: &Scene, q: &[f64]) -> Self {
        let n = scene.n_dof();
        let (mut phi, mut hinge, mut centre) = (vec![0.0; n], vec![[0.0; 2]; n], vec![[0.0; 2]; n]);
        for (i, b) in scene.bodies.iter().enumerate() {
            match b.parent {
                None => {
                    phi[i] = q[i];
                    hinge[i] = b.anchor;
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

    /// Jacobian (2 x n, as rows `[dx/dq; dy/dq]`) of the material point of `body` at world position `p`.
    pub fn point_jacobian(&self, scene: &Scene, body: usize, p: [f64; 2]) -> [Vec<f64>; 2] {
        let n = scene.n_dof();
        let mut jac = [vec![0.0; n], vec![0.0; n]];
        for j in 0..n {
            if scene.moves(j, body) {
                let c = perp(sub(p, self.hinge[j]));
                jac[0][j] = c[0];
                jac[1][j] = c[1];
            }
        }
        jac
    }

    /// Velocity of the material point of `body` at `p` for joint velocities `v`.
    pub fn point_velocity(&self, scene: &Scene, body: usize, p: [f64; 2], v: &[f64]) -> [f64; 2] {
        let mut out = [0.0; 2];
        for (j, vj) in v.iter().enumerate() {
            if scene.moves(j, body) {
                let c = perp(sub(p, self.hinge[j]));
                out[0] += vj * c[0];
                out[1] += vj * c[1];
            }
        }
        out
    }

    /// The mass matrix `M(q) = sum_i m_i Jc_i^T Jc_i + I_i Jw_i^T Jw_i` (row-major `n x n`).
    pub fn mass_matrix(&self, scene: &Scene) -> Vec<f64> {
        let n = scene.n_dof();
        let mut M = vec![0.0; n * n];
        for (i, b) in scene.bodies.iter().enumerate() {
            let jc = self.point_jacobian(scene, i, self.centre[i]);
            for r in 0..n {
                for c in 0..n {
                    let w = if scene.moves(r, i) && scene.moves(c, i) {
                        b.inertia
                    } else {
                        0.0
                    };
                    M[r * n + c] += b.mass * (jc[0][r] * jc[0][c] + jc[1][r] * jc[1][c]) + w;
                }
            }
        }
        M
    }

    /// Bias forces `r(q, v)`: gravity on every centre, `-damping * v` on every joint, and the Coriolis and
    /// centripetal forces `-sum_i m_i Jc_i^T (dJc_i/dt v)`, with `dJc_i/dt v = sum_j v_j perp(dc_i/dt - dh_j/dt)`.
    pub fn bias_forces(&self, scene: &Scene, v: &[f64]) -> Vec<f64> {
        let n = scene.n_dof();
        let mut r: Vec<f64> = scene
            .bodies
            .iter()
            .zip(v)
            .map(|(b, vj)| -b.damping * vj)
            .collect();
        // Hinge velocities: the hinge of j is a point of j's parent.
        let hinge_velocity: Vec<[f64; 2]> = (0..n)
            .map(|j| match scene.bodies[j].parent {
                None => [0.0; 2],
                Some(p) => self.point_velocity(scene, p, self.hinge[j], v),
            })
            .collect();
        for (i, b) in scene.bodies.iter().enumerate() {
            let jc = self.point_jacobian(scene, i, self.centre[i]);
            let cdot = self.point_velocity(scene, i, self.centre[i], v);
            let mut accel = [0.0; 2];
            for j in 0..n {
                if scene.moves(j, i) {
                    let w = perp(sub(cdot, hinge_velocity[j]));
                    accel[0] += v[j] * w[0];
                    accel[1] += v[j] * w[1];
                }
            }
            let f = [
                b.mass * (scene.gravity[0] - accel[0]),
                b.mass * (scene.gravity[1] - accel[1]),
            ];
            for k in 0..n {
                r[k] += jc[0][k] * f[0] + jc[1][k] * f[1];
            }
        }
        r
    }
}
