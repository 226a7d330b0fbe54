//! What the optimiser consumes: discrete dynamics with derivatives, and a cost with derivatives. Matrices
//! are row-major slices (`fx[i * n + j] = d x'_i / d x_j`).

/// Discrete dynamics `x' = f(x, u)` with first derivatives, computed in two stages per knot (as action
/// models and their data are in crocoddyl): [`Dynamics::calc`] computes the step and keeps in the knot's
/// [`Dynamics::Data`] what its linearisation needs; [`Dynamics::calc_diff`] linearises the step `calc`
/// stored there. The model is immutable (`&self`) and everything a knot computes lives in its data, so the
/// optimiser may differentiate the knots of a trajectory on several threads
/// ([`DdpSettings::threads`](crate::DdpSettings::threads)). The optimiser creates one data per knot once per
/// solve (and one per knot for its line search's trial trajectory, swapped in on acceptance), so nothing
/// is looked up by the values of `x` and `u`. Full second-order DDP needs the capability [`SecondOrder`]
/// as well ([`Dynamics::second_order`]).
pub trait Dynamics: Sync {
    /// What a failed step reports (a failed step in a line search is a rejected trial, never propagated).
    type Error: std::error::Error + Send + Sync + 'static;

    /// What one knot's step keeps: for its linearisation, and as the warm start of the next step
    /// computed at that knot (`()` for dynamics in closed form).
    type Data: Send;

    /// `n`, the state's length.
    fn state_dim(&self) -> usize;

    /// `m`, the control's length.
    fn control_dim(&self) -> usize;

    /// Fresh data for one knot.
    fn create_data(&self) -> Self::Data;

    /// Write `f(x, u)` into `next` (length `n`) and keep in `data` what [`Dynamics::calc_diff`] and
    /// [`SecondOrder::calc_diff2`] need. `near`, when given, is the same knot's data from the
    /// trajectory the optimiser is improving (the line search steps near it): dynamics whose step is an
    /// iterative solve may start from the solution it holds. The result must not depend on `near` or on
    /// what `data` held before beyond the solver's tolerance.
    fn calc(
        &self,
        data: &mut Self::Data,
        near: Option<&Self::Data>,
        x: &[f64],
        u: &[f64],
        next: &mut [f64],
    ) -> Result<(), Self::Error>;

    /// Write `fx` (`n x n`) and `fu` (`n x m`) of the step [`Dynamics::calc`] last computed in `data`
    /// (at these `x` and `u`).
    fn calc_diff(
        &self,
        data: &mut Self::Data,
        x: &[f64],
        u: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
    ) -> Result<(), Self::Error>;

    /// The second-order capability, if these dynamics have it (full second-order DDP needs it; without
    /// it only Gauss-Newton iLQR runs). The default: none.
    fn second_order(&self) -> Option<&dyn SecondOrder<Self::Data, Error = Self::Error>> {
        None
    }
}

/// The second-order terms of DDP: the Hessian of `c^T f(x, u)` for the value gradient `c`, in two stages
/// per knot: [`SecondOrder::calc_diff2_prepare`] computes everything that does not depend on `c` once per
/// trajectory (the knots independently, on several threads when asked), and [`SecondOrder::calc_diff2`]
/// contracts it with the `c` of each backward pass (a pass retried with more regularisation at the same
/// trajectory costs the contraction alone).
pub trait SecondOrder<Data>: Sync {
    /// As [`Dynamics::Error`].
    type Error;

    /// The bytes the second-order derivatives keep in one knot's data, estimated before anything is
    /// allocated (0, the default: nothing worth counting). The solver multiplies it by the horizon and
    /// refuses full DDP past [`crate::FULL_DDP_MAX_BYTES`].
    fn bytes_per_knot(&self) -> usize {
        0
    }

    /// Keep in `data` everything of the second derivatives of the step [`Dynamics::calc`] last computed
    /// there (at these `x` and `u`) that does not depend on `c`. The default: nothing (dynamics whose
    /// Hessians are cheap compute them in [`SecondOrder::calc_diff2`]).
    fn calc_diff2_prepare(&self, data: &mut Data, x: &[f64], u: &[f64]) -> Result<(), Self::Error> {
        let _ = (data, x, u);
        Ok(())
    }

    /// Write `fx`, `fu` and the Hessian of `c^T f(x, u)` with respect to `(x, u)` into `hess`
    /// (`(n + m) x (n + m)`), for the step [`Dynamics::calc`] last computed in `data` (at these `x` and
    /// `u`), from what [`SecondOrder::calc_diff2_prepare`] kept there (computing it first if it did not
    /// run).
    #[allow(clippy::too_many_arguments)]
    fn calc_diff2(
        &self,
        data: &mut Data,
        x: &[f64],
        u: &[f64],
        c: &[f64],
        fx: &mut [f64],
        fu: &mut [f64],
        hess: &mut [f64],
    ) -> Result<(), Self::Error>;
}

/// The derivatives of a running cost at one step.
#[derive(Debug, Clone, PartialEq)]
pub struct CostDerivatives {
    /// `dl/dx` (`n`).
    pub lx: Vec<f64>,
    /// `dl/du` (`m`).
    pub lu: Vec<f64>,
    /// `d^2 l/dx^2` (`n x n`).
    pub lxx: Vec<f64>,
    /// `d^2 l/du^2` (`m x m`).
    pub luu: Vec<f64>,
    /// `d^2 l/du dx` (`m x n`).
    pub lux: Vec<f64>,
}

impl CostDerivatives {
    /// Zeros for `n` states and `m` controls.
    pub fn zeros(n: usize, m: usize) -> Self {
        CostDerivatives {
            lx: vec![0.0; n],
            lu: vec![0.0; m],
            lxx: vec![0.0; n * n],
            luu: vec![0.0; m * m],
            lux: vec![0.0; m * n],
        }
    }
}

/// A finite-horizon cost: running costs `l_i(x, u)` and a final cost `l_f(x)`.
pub trait Cost {
    /// `l_i(x, u)` at step `i`.
    fn running(&self, i: usize, x: &[f64], u: &[f64]) -> f64;

    /// `l_f(x)`.
    fn terminal(&self, x: &[f64]) -> f64;

    /// The derivatives of `l_i` at `(x, u)`, every entry of `out` written (it holds another knot's).
    fn running_derivatives(&self, i: usize, x: &[f64], u: &[f64], out: &mut CostDerivatives);

    /// `dl_f/dx` (`n`) and `d^2 l_f/dx^2` (`n x n`), every entry written.
    fn terminal_derivatives(&self, x: &[f64], lx: &mut [f64], lxx: &mut [f64]);
}

/// `l(x, u) = 1/2 (x - x*)^T Q (x - x*) + q^T x + 1/2 u^T R u + r^T u` per step and
/// `l_f(x) = 1/2 (x - x*)^T Q_f (x - x*) + q_f^T x`, the same at every step. With `Q = Q_f = 0` it is the
/// linear state cost of the flicking finger (`-theta3 + c_u |u|^2`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct QuadraticCost {
    /// `x*` (`n`).
    pub target: Vec<f64>,
    /// `Q` (`n x n`, symmetric).
    pub q: Vec<f64>,
    /// Linear state term `q` (`n`).
    pub q_lin: Vec<f64>,
    /// `R` (`m x m`, symmetric).
    pub r: Vec<f64>,
    /// Linear control term `r` (`m`).
    pub r_lin: Vec<f64>,
    /// `Q_f` (`n x n`, symmetric).
    pub qf: Vec<f64>,
    /// Linear final term `q_f` (`n`).
    pub qf_lin: Vec<f64>,
}

impl QuadraticCost {
    /// `1/2 x^T Q x + 1/2 u^T R u` and `1/2 x^T Q_f x` with diagonal weights (target zero, no linear terms).
    pub fn diagonal(q: &[f64], r: &[f64], qf: &[f64]) -> Self {
        let diag = |d: &[f64]| {
            let n = d.len();
            let mut m = vec![0.0; n * n];
            for i in 0..n {
                m[i * n + i] = d[i];
            }
            m
        };
        let n = q.len();
        QuadraticCost {
            target: vec![0.0; n],
            q: diag(q),
            q_lin: vec![0.0; n],
            r: diag(r),
            r_lin: vec![0.0; r.len()],
            qf: diag(qf),
            qf_lin: vec![0.0; n],
        }
    }

    /// A cost linear in the state: `c^T x + c_u |u|^2` per step and `c^T x` at the end.
    pub fn linear_state(c: &[f64], control_weight: f64, m: usize) -> Self {
        let n = c.len();
        let mut r = vec![0.0; m * m];
        for i in 0..m {
            r[i * m + i] = 2.0 * control_weight;
        }
        QuadraticCost {
            target: vec![0.0; n],
            q: vec![0.0; n * n],
            q_lin: c.to_vec(),
            r,
            r_lin: vec![0.0; m],
            qf: vec![0.0; n * n],
            qf_lin: c.to_vec(),
        }
    }

    fn m(&self) -> usize {
        self.r_lin.len()
    }

    /// `Err` unless every size matches `n`, `m` and every entry is finite.
    pub fn validate(&self, n: usize, m: usize) -> Result<(), crate::DdpError> {
        let fields: [(&'static str, &[f64], usize); 7] = [
            ("cost target", &self.target, n),
            ("cost Q", &self.q, n * n),
            ("cost q", &self.q_lin, n),
            ("cost R", &self.r, m * m),
            ("cost r", &self.r_lin, m),
            ("cost Q_f", &self.qf, n * n),
            ("cost q_f", &self.qf_lin, n),
        ];
        for (what, v, len) in fields {
            crate::check(what, v, len)?;
        }
        Ok(())
    }

    fn quad(m: &[f64], a: &[f64], b: &[f64]) -> f64 {
        let n = a.len();
        let mut s = 0.0;
        for i in 0..n {
            for j in 0..n {
                s += a[i] * m[i * n + j] * b[j];
            }
        }
        s
    }

    /// `(x - x*)^T W (x - x*)` without allocating `x - x*` (the same arithmetic, in the same order).
    fn quad_offset(&self, w: &[f64], x: &[f64]) -> f64 {
        let (n, t) = (x.len(), &self.target);
        let mut s = 0.0;
        for i in 0..n {
            let di = x[i] - t[i];
            for j in 0..n {
                s += di * w[i * n + j] * (x[j] - t[j]);
            }
        }
        s
    }

    /// `q_lin + W (x - x*)` into `out`.
    fn gradient_into(&self, out: &mut [f64], w: &[f64], lin: &[f64], x: &[f64]) {
        let (n, t) = (x.len(), &self.target);
        for i in 0..n {
            out[i] = lin[i] + (0..n).map(|j| w[i * n + j] * (x[j] - t[j])).sum::<f64>();
        }
    }

    fn dot(a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(x, y)| x * y).sum()
    }
}

impl Cost for QuadraticCost {
    fn running(&self, _i: usize, x: &[f64], u: &[f64]) -> f64 {
        0.5 * self.quad_offset(&self.q, x)
            + Self::dot(&self.q_lin, x)
            + 0.5 * Self::quad(&self.r, u, u)
            + Self::dot(&self.r_lin, u)
    }

    fn terminal(&self, x: &[f64]) -> f64 {
        0.5 * self.quad_offset(&self.qf, x) + Self::dot(&self.qf_lin, x)
    }

    fn running_derivatives(&self, _i: usize, x: &[f64], u: &[f64], out: &mut CostDerivatives) {
        let m = self.m();
        self.gradient_into(&mut out.lx, &self.q, &self.q_lin, x);
        for i in 0..m {
            out.lu[i] = self.r_lin[i] + (0..m).map(|j| self.r[i * m + j] * u[j]).sum::<f64>();
        }
        out.lxx.copy_from_slice(&self.q);
        out.luu.copy_from_slice(&self.r);
        out.lux.iter_mut().for_each(|e| *e = 0.0);
    }

    fn terminal_derivatives(&self, x: &[f64], lx: &mut [f64], lxx: &mut [f64]) {
        self.gradient_into(lx, &self.qf, &self.qf_lin, x);
        lxx.copy_from_slice(&self.qf);
    }
}
