//! The solver's workspace, allocated once per solve, and the stages of its backward pass over it: the
//! expansion of Q (eq. 11), its regularisation, the gains (by Cholesky, or by the box QP under control
//! limits), and the value's update. The forward pass's trial trajectory lives here too, swapped with the
//! accepted one on acceptance.

use crate::boxqp;
use crate::linalg::{
    cholesky_into, cholesky_solve, mul_into, mul_tn_into, mul_tv_into, symmetrize,
};
use crate::model::CostDerivatives;
use crate::settings::{ControlLimits, Regularisation};

/// Everything a solve writes as it goes, sized once for `n` states, `m` controls and its horizon.
pub(crate) struct Workspace {
    n: usize,
    m: usize,
    /// The step's derivatives at the knot being expanded, and (full DDP) the Hessian of `V_x . f`.
    pub(crate) fx: Vec<f64>,
    pub(crate) fu: Vec<f64>,
    pub(crate) hess: Vec<f64>,
    /// The running cost's derivatives at the knot.
    pub(crate) cd: CostDerivatives,
    /// The value's expansion carried backwards: at the knot after the one being expanded, then at it.
    pub(crate) vx: Vec<f64>,
    pub(crate) vxx: Vec<f64>,
    qx: Vec<f64>,
    qu: Vec<f64>,
    qxx: Vec<f64>,
    qux: Vec<f64>,
    quu: Vec<f64>,
    qux_reg: Vec<f64>,
    quu_reg: Vec<f64>,
    vxx_fx: Vec<f64>,
    vxx_fu: Vec<f64>,
    reg_ux: Vec<f64>,
    reg_uu: Vec<f64>,
    chol: Vec<f64>,
    quu_k: Vec<f64>,
    quu_bk: Vec<f64>,
    tmp_n: Vec<f64>,
    tmp_nn: Vec<f64>,
    /// The backward pass's feedforward steps `k_i` and gains `K_i` (read once it succeeds).
    pub(crate) k: Vec<Vec<f64>>,
    pub(crate) gains: Vec<Vec<f64>>,
    /// `[sum k^T Q_u, sum 1/2 k^T Q_uu k]`.
    pub(crate) dv: [f64; 2],
    /// The line search's trial trajectory.
    pub(crate) x_trial: Vec<Vec<f64>>,
    pub(crate) u_trial: Vec<Vec<f64>>,
    /// Gauss-Newton's linearisation of the accepted trajectory, and whether it is current.
    pub(crate) lin_fx: Vec<Vec<f64>>,
    pub(crate) lin_fu: Vec<Vec<f64>>,
    pub(crate) lin_current: bool,
}

impl Workspace {
    pub(crate) fn new(n: usize, m: usize, horizon: usize) -> Self {
        let nm = n + m;
        let z = |len: usize| vec![0.0; len];
        Workspace {
            n,
            m,
            fx: z(n * n),
            fu: z(n * m),
            hess: z(nm * nm),
            cd: CostDerivatives::zeros(n, m),
            vx: z(n),
            vxx: z(n * n),
            qx: z(n),
            qu: z(m),
            qxx: z(n * n),
            qux: z(m * n),
            quu: z(m * m),
            qux_reg: z(m * n),
            quu_reg: z(m * m),
            vxx_fx: z(n * n),
            vxx_fu: z(n * m),
            reg_ux: z(m * n),
            reg_uu: z(m * m),
            chol: z(m * m),
            quu_k: z(m),
            quu_bk: z(m * n),
            tmp_n: z(n),
            tmp_nn: z(n * n),
            k: vec![z(m); horizon],
            gains: vec![z(m * n); horizon],
            dv: [0.0; 2],
            x_trial: vec![z(n); horizon + 1],
            u_trial: vec![z(m); horizon],
            lin_fx: Vec::new(),
            lin_fu: Vec::new(),
            lin_current: false,
        }
    }

    /// Stage 1: Q's expansion (eq. 11) at a knot from `fx`, `fu`, the cost's derivatives `cd`, the value
    /// `(vx, vxx)` of the next knot and, in full DDP, the Hessian `hess` of `V_x . f` over `(x, u)`.
    pub(crate) fn q_expansion(&mut self, full: bool) {
        let (n, m) = (self.n, self.m);
        let (fx, fu, cd) = (&self.fx, &self.fu, &self.cd);
        mul_tv_into(&mut self.qx, fx, &self.vx, n, n);
        mul_tv_into(&mut self.qu, fu, &self.vx, n, m);
        for (a, b) in self.qx.iter_mut().zip(&cd.lx) {
            *a += b;
        }
        for (a, b) in self.qu.iter_mut().zip(&cd.lu) {
            *a += b;
        }
        mul_into(&mut self.vxx_fx, &self.vxx, fx, n, n, n);
        mul_into(&mut self.vxx_fu, &self.vxx, fu, n, n, m);
        mul_tn_into(&mut self.qxx, fx, &self.vxx_fx, n, n, n);
        mul_tn_into(&mut self.qux, fu, &self.vxx_fx, n, m, n);
        mul_tn_into(&mut self.quu, fu, &self.vxx_fu, n, m, m);
        for (a, b) in self.qxx.iter_mut().zip(&cd.lxx) {
            *a += b;
        }
        for (a, b) in self.qux.iter_mut().zip(&cd.lux) {
            *a += b;
        }
        for (a, b) in self.quu.iter_mut().zip(&cd.luu) {
            *a += b;
        }
        if full {
            // `hess` is `(n + m) x (n + m)`: its first n rows add to Q_xx, the others split into
            // Q_ux's row and Q_uu's.
            let nm = n + m;
            let (hx, hu) = self.hess[..nm * nm].split_at(n * nm);
            // (Chunk lengths of at least one: an empty state or control space adds nothing.)
            for (q, h) in self
                .qxx
                .chunks_exact_mut(n.max(1))
                .zip(hx.chunks_exact(nm.max(1)))
            {
                for (a, b) in q.iter_mut().zip(&h[..n]) {
                    *a += b;
                }
            }
            let rows = self
                .qux
                .chunks_exact_mut(n.max(1))
                .zip(self.quu.chunks_exact_mut(m.max(1)));
            for ((qx, qu), h) in rows.zip(hu.chunks_exact(nm.max(1))) {
                let (hx, hu) = h.split_at(n);
                for (a, b) in qx.iter_mut().zip(hx) {
                    *a += b;
                }
                for (a, b) in qu.iter_mut().zip(hu) {
                    *a += b;
                }
            }
        }
        symmetrize(&mut self.quu, m);
    }

    /// Stage 2: the regularised pair `(Q_ux, Q_uu)` that gives the policy (the value's update uses the
    /// plain Q; Tassa, Erez and Todorov 2012).
    pub(crate) fn regularise(&mut self, mu: f64, kind: Regularisation) {
        let (n, m) = (self.n, self.m);
        self.qux_reg.copy_from_slice(&self.qux);
        self.quu_reg.copy_from_slice(&self.quu);
        if mu > 0.0 {
            match kind {
                Regularisation::State => {
                    mul_tn_into(&mut self.reg_ux, &self.fu, &self.fx, n, m, n);
                    mul_tn_into(&mut self.reg_uu, &self.fu, &self.fu, n, m, m);
                    for (a, b) in self.qux_reg.iter_mut().zip(&self.reg_ux) {
                        *a += mu * b;
                    }
                    for (a, b) in self.quu_reg.iter_mut().zip(&self.reg_uu) {
                        *a += mu * b;
                    }
                }
                Regularisation::Control => {
                    for a in 0..m {
                        self.quu_reg[a * m + a] += mu;
                    }
                }
            }
        }
    }

    /// Stage 3: knot `i`'s feedforward step and gains, by Cholesky, or under control `limits` by the
    /// box QP (warm-started from `k_prev`, the bounds relative to the control `u`). False when the
    /// regularised `Q_uu` is not positive definite.
    pub(crate) fn gains(
        &mut self,
        i: usize,
        limits: Option<&ControlLimits>,
        u: &[f64],
        k_prev: &[f64],
    ) -> bool {
        let (n, m) = (self.n, self.m);
        match limits {
            None => {
                if !cholesky_into(&mut self.chol, &self.quu_reg, m) {
                    return false;
                }
                let k = &mut self.k[i];
                for (a, q) in k.iter_mut().zip(&self.qu) {
                    *a = -q;
                }
                cholesky_solve(&self.chol, m, k, 1);
                let big_k = &mut self.gains[i];
                for (a, q) in big_k.iter_mut().zip(&self.qux_reg) {
                    *a = -q;
                }
                cholesky_solve(&self.chol, m, big_k, n);
            }
            Some(lim) => {
                let lower: Vec<f64> = (0..m).map(|j| lim.lower[j] - u[j]).collect();
                let upper: Vec<f64> = (0..m).map(|j| lim.upper[j] - u[j]).collect();
                let Some(qp) = boxqp::solve(&self.quu_reg, &self.qu, &lower, &upper, k_prev) else {
                    return false;
                };
                let big_k = &mut self.gains[i];
                big_k.iter_mut().for_each(|e| *e = 0.0);
                if let Some(l) = &qp.free_factor {
                    let free: Vec<usize> = (0..m).filter(|&j| !qp.clamped[j]).collect();
                    let nf = free.len();
                    let mut rhs = vec![0.0; nf * n];
                    for (a, &j) in free.iter().enumerate() {
                        for b in 0..n {
                            rhs[a * n + b] = -self.qux_reg[j * n + b];
                        }
                    }
                    cholesky_solve(l, nf, &mut rhs, n);
                    for (a, &j) in free.iter().enumerate() {
                        big_k[j * n..(j + 1) * n].copy_from_slice(&rhs[a * n..(a + 1) * n]);
                    }
                }
                self.k[i].copy_from_slice(&qp.x);
            }
        }
        true
    }

    /// Stage 4: the expected reduction and the value's expansion at knot `i` (into `vx`, `vxx`):
    /// `V_x = Q_x + K^T Q_uu k + K^T Q_u + Q_ux^T k`, `V_xx = Q_xx + K^T Q_uu K + K^T Q_ux + Q_ux^T K`.
    /// False when it is not finite.
    pub(crate) fn value_update(&mut self, i: usize) -> bool {
        let (n, m) = (self.n, self.m);
        let (k, big_k) = (&self.k[i], &self.gains[i]);
        mul_into(&mut self.quu_k, &self.quu, k, m, m, 1);
        self.dv[0] += k.iter().zip(&self.qu).map(|(a, b)| a * b).sum::<f64>();
        self.dv[1] += 0.5 * k.iter().zip(&self.quu_k).map(|(a, b)| a * b).sum::<f64>();
        for (a, b) in self.quu_k.iter_mut().zip(&self.qu) {
            *a += b;
        }
        mul_tv_into(&mut self.tmp_n, big_k, &self.quu_k, m, n);
        self.vx.copy_from_slice(&self.qx);
        for (a, b) in self.vx.iter_mut().zip(&self.tmp_n) {
            *a += b;
        }
        mul_tv_into(&mut self.tmp_n, &self.qux, k, m, n);
        for (a, b) in self.vx.iter_mut().zip(&self.tmp_n) {
            *a += b;
        }
        mul_into(&mut self.quu_bk, &self.quu, big_k, m, m, n);
        for (a, b) in self.quu_bk.iter_mut().zip(&self.qux) {
            *a += 2.0 * b;
        }
        // K^T (Q_uu K + 2 Q_ux), symmetrised: K^T Q_uu K + K^T Q_ux + Q_ux^T K.
        mul_tn_into(&mut self.tmp_nn, big_k, &self.quu_bk, m, n, n);
        self.vxx.copy_from_slice(&self.qxx);
        for (a, b) in self.vxx.iter_mut().zip(&self.tmp_nn) {
            *a += b;
        }
        symmetrize(&mut self.vxx, n);
        self.vx.iter().chain(&self.vxx).all(|e| e.is_finite())
    }
}
