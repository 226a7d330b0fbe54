//! The step's equations as functions: their residual at a given solution `z = [v'; lambda]`, in any scalar
//! type (for tests and for differences against the implicit-function derivatives).

#![allow(non_snake_case)]

use crate::constraint::Constraints;
use crate::error::DynamicsError;
use crate::kinematics::{Kinematics, Scalar};
use crate::scene::Scene;

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
