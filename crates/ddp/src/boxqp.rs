//! The box-constrained quadratic program of control-limited DDP (Tassa, Mansard and Todorov, ICRA 2014):
//! `min 1/2 x^T H x + g^T x` subject to `lower <= x <= upper`, by projected Newton on the free set with an
//! Armijo search along the projection arc.

use crate::linalg::{cholesky, cholesky_solve};

/// The solution of a box QP.
#[derive(Debug, Clone)]
pub struct BoxQp {
    /// The minimiser.
    pub x: Vec<f64>,
    /// Whether each entry is clamped at a bound with the gradient pushing outwards.
    pub clamped: Vec<bool>,
    /// Cholesky factor of `H` restricted to the free entries (`None` when every entry is clamped).
    pub free_factor: Option<Vec<f64>>,
}

/// Solve the box QP from the start `x0` (clamped into the box). `None` when `H` restricted to the free set
/// is not positive definite.
pub fn solve(h: &[f64], g: &[f64], lower: &[f64], upper: &[f64], x0: &[f64]) -> Option<BoxQp> {
    let n = g.len();
    let clamp = |x: &mut [f64]| {
        for i in 0..n {
            x[i] = x[i].clamp(lower[i], upper[i]);
        }
    };
    let value = |x: &[f64]| {
        let mut v = 0.0;
        for i in 0..n {
            v += g[i] * x[i];
            for j in 0..n {
                v += 0.5 * x[i] * h[i * n + j] * x[j];
            }
        }
        v
    };
    let mut x = x0.to_vec();
    clamp(&mut x);
    let mut clamped = vec![false; n];
    let mut factor: Option<Vec<f64>> = None;
    let mut old_clamped: Option<Vec<bool>> = None;
    let mut val = value(&x);
    for _ in 0..100 {
        let grad: Vec<f64> = (0..n)
            .map(|i| g[i] + (0..n).map(|j| h[i * n + j] * x[j]).sum::<f64>())
            .collect();
        for i in 0..n {
            clamped[i] = (x[i] <= lower[i] && grad[i] > 0.0) || (x[i] >= upper[i] && grad[i] < 0.0);
        }
        let free: Vec<usize> = (0..n).filter(|&i| !clamped[i]).collect();
        if free.is_empty() {
            factor = None;
            break;
        }
        if old_clamped.as_ref() != Some(&clamped) || factor.is_none() {
            let nf = free.len();
            let mut hf = vec![0.0; nf * nf];
            for (a, &i) in free.iter().enumerate() {
                for (b, &j) in free.iter().enumerate() {
                    hf[a * nf + b] = h[i * n + j];
                }
            }
            factor = Some(cholesky(&hf, nf)?);
            old_clamped = Some(clamped.clone());
        }
        let gnorm: f64 = free.iter().map(|&i| grad[i] * grad[i]).sum::<f64>().sqrt();
        if gnorm < 1e-10 {
            break;
        }
        // Newton direction on the free entries, zero on the clamped ones.
        let l = factor.as_ref().expect("factored above");
        let mut step: Vec<f64> = free.iter().map(|&i| -grad[i]).collect();
        cholesky_solve(l, free.len(), &mut step, 1);
        let mut dir = vec![0.0; n];
        for (a, &i) in free.iter().enumerate() {
            dir[i] = step[a];
        }
        let sdotg: f64 = (0..n).map(|i| dir[i] * grad[i]).sum();
        if sdotg >= 0.0 {
            break;
        }
        let mut t = 1.0;
        let mut accepted = false;
        while t > 1e-20 {
            let mut trial: Vec<f64> = (0..n).map(|i| x[i] + t * dir[i]).collect();
            clamp(&mut trial);
            let tv = value(&trial);
            if tv - val <= 0.1 * t * sdotg {
                let moved = (0..n).map(|i| (trial[i] - x[i]).abs()).fold(0.0, f64::max);
                x = trial;
                val = tv;
                accepted = moved > 0.0;
                break;
            }
            t *= 0.6;
        }
        if !accepted {
            break;
        }
    }
    Some(BoxQp {
        x,
        clamped,
        free_factor: factor,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_interior_minimum_is_the_newton_step_and_a_clamped_one_sits_on_its_bound() {
        let h = [2.0, 0.5, 0.5, 1.0];
        let g = [-1.0, -1.0];
        let free = solve(&h, &g, &[-10.0; 2], &[10.0; 2], &[0.0; 2]).unwrap();
        // H x = -g.
        for i in 0..2 {
            let r: f64 = (0..2).map(|j| h[i * 2 + j] * free.x[j]).sum::<f64>() + g[i];
            assert!(r.abs() < 1e-12);
        }
        assert_eq!(free.clamped, vec![false, false]);
        let boxed = solve(&h, &g, &[-10.0, -10.0], &[10.0, 0.2], &[0.0; 2]).unwrap();
        assert_eq!(boxed.x[1], 0.2);
        assert_eq!(boxed.clamped, vec![false, true]);
        // The free entry minimises with the other fixed: 2 x0 + 0.5 * 0.2 - 1 = 0.
        assert!((boxed.x[0] - 0.45).abs() < 1e-12);
    }
}
