//! Stage 1 of the derivatives: the step's ingredients (`M`, `r + B u`, `J`, `d` and each row's noise) with
//! their derivatives in `y = (x, u)`.
//!
//! First derivatives run in vector duals over eight entries of `y` per pass ([`Ingredients`]). Second
//! derivatives ([`Expansion`]) exploit the ingredients' structure: `M`, `J`, `d` and the noise are functions
//! of `q` alone, the forces of `(q, v)` (affine in `u`); each group is expanded to second order over its own
//! arguments in fused jets ([`Jet`]), in one pass where they fit the jet's directions and otherwise in one
//! pass per pair of blocks of directions, so a scene of any size gets its exact Hessians.

#![allow(non_snake_case)]

use crate::constraint::{Constraints, ContactFrame};
use crate::error::DynamicsError;
use crate::jet::{Jet, Jet1};
use nalgebra::{SMatrix, SVector};
use num_dual::{Derivative, Dual2SVec64, DualSVec64};

/// Directions of a vector-dual pass over `y = (x, u)`: the finger's 6 state and 2 control entries at once.
pub(super) const DIRECTIONS: usize = 8;

pub(super) type D1 = DualSVec64<DIRECTIONS>;
pub(super) type D2 = Dual2SVec64<DIRECTIONS>;
/// The first derivatives' ingredients, all of one chunk of `y` at once.
pub(super) type F1 = Jet1<DIRECTIONS>;

/// The step's ingredients at `(x, u)` in some scalar type: `M`, `r + B u`, `J`, `d` and each row's noise.
pub(super) struct Ingredients<T> {
    pub(super) contacts: Vec<ContactFrame>,
    /// Each row's distance `d(q)` (the step reports it; `d` below is what the rows see,
    /// [`crate::StepSettings::recovery`]).
    pub(super) distance: Vec<f64>,
    pub(super) M: Vec<T>,
    pub(super) r: Vec<T>,
    pub(super) jac: Vec<T>,
    pub(super) d: Vec<T>,
    pub(super) sigma: Vec<T>,
    /// The position-level correction `dq(q)` ([`Model::position_correction`]), `n`.
    pub(super) correction: Vec<T>,
}

impl<T> Ingredients<T> {
    /// No ingredients yet (vectors to be filled).
    pub(super) fn empty() -> Self {
        Ingredients {
            contacts: Vec::new(),
            distance: Vec::new(),
            M: Vec::new(),
            r: Vec::new(),
            jac: Vec::new(),
            d: Vec::new(),
            sigma: Vec::new(),
            correction: Vec::new(),
        }
    }
}

/// Values, gradients and Hessians of a list of functions of `dim` arguments, stored flat: function `i`'s
/// gradient is `g[i dim..(i + 1) dim]`, its Hessian's upper triangle the `dim (dim + 1) / 2` entries after
/// `i dim (dim + 1) / 2` of `h`, packed row by row as a [`Jet`] keeps it (`(0, 0), (0, 1), .., (1, 1), ..`):
/// the one-pass expansion copies it as it is, and the contraction reads only the upper triangle.
#[derive(Default)]
pub(super) struct Taylor {
    dim: usize,
    re: Vec<f64>,
    g: Vec<f64>,
    h: Vec<f64>,
}

#[cfg(test)]
impl Taylor {
    /// Every number it holds, as bits: for comparing two expansions exactly.
    pub(super) fn bits(&self) -> Vec<u64> {
        self.re
            .iter()
            .chain(&self.g)
            .chain(&self.h)
            .map(|e| e.to_bits())
            .collect()
    }
}

/// The length of a packed upper triangle of a `dim x dim` matrix.
pub(super) const fn packed_len(dim: usize) -> usize {
    dim * (dim + 1) / 2
}

/// The index of entry `(a, b)`, `a <= b`, in a packed upper triangle of a `dim x dim` matrix: rows
/// `0..a` hold `dim + (dim - 1) + .. + (dim - a + 1)` entries.
#[inline]
pub(super) fn packed_at(dim: usize, a: usize, b: usize) -> usize {
    debug_assert!(a <= b && b < dim);
    a * dim - a * a.saturating_sub(1) / 2 + (b - a)
}

impl Taylor {
    /// The number of arguments.
    pub(super) fn dim(&self) -> usize {
        self.dim
    }

    /// Function `i`'s value.
    pub(super) fn re(&self, i: usize) -> f64 {
        self.re[i]
    }

    /// Function `i`'s gradient (`dim`).
    pub(super) fn g(&self, i: usize) -> &[f64] {
        &self.g[i * self.dim..(i + 1) * self.dim]
    }

    /// Function `i`'s Hessian, its upper triangle packed row by row ([`packed_at`]).
    pub(super) fn h(&self, i: usize) -> &[f64] {
        let dd = packed_len(self.dim);
        &self.h[i * dd..(i + 1) * dd]
    }

    /// Entry `(a, b)` of function `i`'s Hessian.
    pub(super) fn hessian(&self, i: usize, a: usize, b: usize) -> f64 {
        let (a, b) = if a <= b { (a, b) } else { (b, a) };
        self.h(i)[packed_at(self.dim, a, b)]
    }

    /// The functions `f` of `dim` arguments at `at`, to second order, evaluated in `K`-direction jets: in
    /// one pass when `dim <= K`; otherwise the arguments are cut into blocks of `K / 2` and each pair of
    /// blocks takes one pass (its jets carry both blocks' directions), which together cover every
    /// gradient entry and every block of the Hessian. `f` hands its values, in order, to the [`Sink`];
    /// `len` is how many there are. The coefficients go into `taylor`'s vectors (refilled: no allocation
    /// once they have the sizes) and the arguments' jets into `args`.
    pub(super) fn expand<const K: usize, const H: usize>(
        taylor: &mut Taylor,
        at: &[f64],
        len: usize,
        args: &mut Vec<Jet<K, H>>,
        mut f: impl FnMut(&[Jet<K, H>], &mut Sink<'_>) -> Result<(), DynamicsError>,
    ) -> Result<(), DynamicsError> {
        let dim = at.len();
        taylor.dim = dim;
        // Every entry is written below (the one pass, or the pairs of blocks, which cover every block of
        // the Hessian), so vectors already of the right length are not cleared.
        for (v, size) in [
            (&mut taylor.re, len),
            (&mut taylor.g, len * dim),
            (&mut taylor.h, len * packed_len(dim)),
        ] {
            v.resize(size, 0.0);
        }
        let mut pass = |dirs: &[usize], first: bool| -> Result<(), DynamicsError> {
            seed(args, at, dirs);
            f(args, &mut Sink::new(taylor, dirs, first))
        };
        const { assert!(K <= ALL_DIRECTIONS.len()) };
        if dim <= K {
            // The usual case, one pass over all arguments: no list of passes to build.
            pass(&ALL_DIRECTIONS[..dim], true)?;
        } else {
            for (i, dirs) in block_pairs(dim, K).iter().enumerate() {
                pass(dirs, i == 0)?;
            }
        }
        Ok(())
    }

    /// `len` functions of `dim` arguments, all zero: what [`Taylor::expand_over`] fills in part by part.
    pub(super) fn zeroed(&mut self, dim: usize, len: usize) {
        self.dim = dim;
        for (v, size) in [
            (&mut self.re, len),
            (&mut self.g, len * dim),
            (&mut self.h, len * packed_len(dim)),
        ] {
            v.clear();
            v.resize(size, 0.0);
        }
    }

    /// [`Taylor::expand`] over the arguments `over` alone, the others held constant, for functions that
    /// depend on no other argument: the functions `select` (indices in the order `f` hands them over)
    /// get their values and their gradient and Hessian entries among `over`; the others, and the entries
    /// that mix `over` with another argument, are left as they are (zero after [`Taylor::zeroed`]). One
    /// pass when `over` fits the jet's `K` directions, otherwise one per pair of blocks of it.
    pub(super) fn expand_over<const K: usize, const H: usize>(
        taylor: &mut Taylor,
        at: &[f64],
        (over, select): (&[usize], &[usize]),
        args: &mut Vec<Jet<K, H>>,
        mut f: impl FnMut(&[Jet<K, H>], &mut Sink<'_>) -> Result<(), DynamicsError>,
    ) -> Result<(), DynamicsError> {
        debug_assert_eq!(taylor.dim, at.len());
        let mut pass = |dirs: &[usize]| -> Result<(), DynamicsError> {
            seed(args, at, dirs);
            let mut sink = Sink::new(taylor, dirs, false);
            sink.select = Some(select);
            f(args, &mut sink)
        };
        if over.len() <= K {
            pass(over)?;
        } else {
            for block in block_pairs(over.len(), K) {
                let dirs: Vec<usize> = block.iter().map(|&l| over[l]).collect();
                pass(&dirs)?;
            }
        }
        Ok(())
    }
}

/// The arguments `at` as jets into `args` (refilled): argument `dirs[l]` the variable of direction `l`,
/// the others constants.
fn seed<const K: usize, const H: usize>(args: &mut Vec<Jet<K, H>>, at: &[f64], dirs: &[usize]) {
    args.clear();
    args.extend(
        at.iter()
            .enumerate()
            .map(|(i, &v)| match dirs.iter().position(|&d| d == i) {
                Some(l) => Jet::variable(v, l),
                None => Jet::from(v),
            }),
    );
}

/// The directions `0, 1, ...` of the one pass over all of at most `K` arguments.
const ALL_DIRECTIONS: [usize; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15];

/// The passes of directions that give every second derivative of `dim` arguments with `width` directions
/// per pass: all of them in one pass when they fit, otherwise the arguments cut into blocks of `width / 2`
/// and one pass per pair of blocks (which together cover every gradient entry and every block of the
/// Hessian).
pub(super) fn block_pairs(dim: usize, width: usize) -> Vec<Vec<usize>> {
    if dim <= width {
        return vec![(0..dim).collect()];
    }
    let half = (width / 2).max(1);
    let blocks: Vec<Vec<usize>> = (0..dim)
        .step_by(half)
        .map(|s| (s..(s + half).min(dim)).collect())
        .collect();
    let mut passes = Vec::new();
    for a in 0..blocks.len() {
        for b in a + 1..blocks.len() {
            passes.push([blocks[a].as_slice(), blocks[b].as_slice()].concat());
        }
    }
    passes
}

/// Where one pass of [`Taylor::expand`] writes its functions' values, gradient and Hessian entries (its
/// directions `dirs` of the arguments), in the order they are handed over.
pub(super) struct Sink<'a> {
    taylor: &'a mut Taylor,
    dirs: &'a [usize],
    /// Whether this pass creates the functions (the first), or fills in entries of existing ones.
    first: bool,
    next: usize,
    /// The functions whose values and entries this pass writes, when not all
    /// ([`Taylor::expand_over`]).
    select: Option<&'a [usize]>,
}

impl<'a> Sink<'a> {
    pub(super) fn new(taylor: &'a mut Taylor, dirs: &'a [usize], first: bool) -> Self {
        Sink {
            taylor,
            dirs,
            first,
            next: 0,
            select: None,
        }
    }

    /// Whether this pass is the first (which creates the functions).
    pub(super) fn first(&self) -> bool {
        self.first
    }

    /// The next functions' values in jets.
    pub(super) fn emit<const K: usize, const H: usize>(&mut self, values: &[Jet<K, H>]) {
        let t = &mut *self.taylor;
        let dim = t.dim;
        let dd = packed_len(dim);
        let whole = self.dirs.len() == dim;
        for v in values {
            let o = self.next;
            self.next += 1;
            if let Some(select) = self.select {
                if !select.contains(&o) {
                    continue;
                }
                t.re[o] = v.re;
            }
            if self.first {
                t.re[o] = v.re;
                if whole {
                    // The one pass over all arguments, in order: the gradient's leading entries, and the
                    // Hessian's packed rows (all of the jet's when its width is the arguments').
                    let packed = v.packed();
                    if dim == K && dd == H {
                        // Whole jets: copies of the jet's own sizes, which compile to a few moves
                        // where slices of the run-time sizes called memcpy.
                        let g: &mut [f64; K] = (&mut t.g[o * K..(o + 1) * K])
                            .try_into()
                            .expect("K entries");
                        *g = v.g;
                        let hb: &mut [f64; H] = (&mut t.h[o * H..(o + 1) * H])
                            .try_into()
                            .expect("H entries");
                        *hb = *packed;
                    } else if dim == K {
                        t.g[o * dim..(o + 1) * dim].copy_from_slice(&v.g[..dim]);
                        t.h[o * dd..(o + 1) * dd].copy_from_slice(&packed[..dd]);
                    } else {
                        t.g[o * dim..(o + 1) * dim].copy_from_slice(&v.g[..dim]);
                        let hb = &mut t.h[o * dd..(o + 1) * dd];
                        let (mut from, mut to) = (0, 0);
                        for i in 0..dim {
                            hb[to..to + dim - i].copy_from_slice(&packed[from..from + dim - i]);
                            to += dim - i;
                            from += K - i;
                        }
                    }
                    continue;
                }
            }
            let hb = &mut t.h[o * dd..(o + 1) * dd];
            for (l, &i) in self.dirs.iter().enumerate() {
                t.g[o * dim + i] = v.g[l];
                for (l2, &j) in self.dirs.iter().enumerate() {
                    if i <= j {
                        hb[packed_at(dim, i, j)] = v.hessian(l, l2);
                    }
                }
            }
        }
    }
}

/// The second-order ingredients before lifting: functions of `q` (the geometry: `M`, `J`, `d` and the
/// noise, one [`Taylor`] over `n` arguments) and the forces, a function of `(q, v)` (over `2n`); the forces
/// hold `B u` in value only (they are affine in `u`, whose directions are added on lifting).
#[derive(Default)]
pub(super) struct Expansion {
    pub(super) n: usize,
    /// Complementarity rows.
    pub(super) m: usize,
    pub(super) contacts: Vec<ContactFrame>,
    pub(super) distance: Vec<f64>,
    /// `(joint, direction of its control in y)`.
    pub(super) actuated: Vec<(usize, usize)>,
    /// `M` (`n x n`), then `J` (`m x n`), then `d` (`m`), then the noise (`m`), then the position-level
    /// correction (`n`), over `q`.
    pub(super) geometry: Taylor,
    /// `r(q, v)` with `B u` (`n`), over `(q, v)`.
    pub(super) forces: Taylor,
    /// The directions of one tree's forces pass (kept to be refilled).
    pub(super) over: Vec<usize>,
}

impl Expansion {
    /// Index of `M_ij` in [`Expansion::geometry`].
    pub(super) fn mass(&self, i: usize, j: usize) -> usize {
        i * self.n + j
    }

    /// Index of `J_kj`.
    pub(super) fn jac(&self, k: usize, j: usize) -> usize {
        self.n * self.n + k * self.n + j
    }

    /// Index of `d_k`.
    pub(super) fn dist(&self, k: usize) -> usize {
        self.n * (self.n + self.m) + k
    }

    /// Index of row `k`'s noise.
    pub(super) fn noise(&self, k: usize) -> usize {
        self.n * (self.n + self.m) + self.m + k
    }

    /// Index of entry `i` of the position-level correction.
    pub(super) fn correction(&self, i: usize) -> usize {
        self.n * (self.n + self.m) + 2 * self.m + i
    }

    /// The ingredients as numbers over the directions `dirs` of `y`, from each function's value, its
    /// gradient entry `grad(t, i, y)` and Hessian entry `hess(t, i, y, y')` (zero where `y`, `y'` are not
    /// among the function's arguments), and the controls' directions `unit(l)` (for `B u`).
    fn convert<T: std::ops::AddAssign + Copy>(
        &self,
        dirs: &[usize],
        lift: impl Fn(&Taylor, usize, &[usize]) -> T,
        unit: impl Fn(usize) -> T,
    ) -> Ingredients<T> {
        let n = self.n;
        let m = self.m;
        let map = |range: std::ops::Range<usize>| {
            range
                .map(|i| lift(&self.geometry, i, dirs))
                .collect::<Vec<T>>()
        };
        let mut forces: Vec<T> = (0..n).map(|i| lift(&self.forces, i, dirs)).collect();
        for &(j, k) in &self.actuated {
            if let Some(l) = dirs.iter().position(|&y| y == k) {
                forces[j] += unit(l);
            }
        }
        Ingredients {
            contacts: self.contacts.clone(),
            distance: self.distance.clone(),
            M: map(0..n * n),
            r: forces,
            jac: map(n * n..n * n + m * n),
            d: map(self.dist(0)..self.dist(m)),
            sigma: map(self.noise(0)..self.noise(m)),
            correction: map(self.correction(0)..self.correction(n)),
        }
    }

    /// The ingredients' values: `M`, `r + B u` and the constraints (true distances) at the step's start,
    /// into the vectors given (refilled).
    pub(super) fn values_into(
        &self,
        mass: &mut Vec<f64>,
        r: &mut Vec<f64>,
        cons: &mut Constraints,
    ) {
        let (n, m, geo) = (self.n, self.m, &self.geometry);
        cons.d.clear();
        cons.d.extend_from_slice(&self.distance);
        cons.jacobian.clear();
        cons.jacobian
            .extend((0..m * n).map(|e| geo.re(self.jac(e / n, e % n))));
        cons.contacts.clear();
        cons.contacts.extend_from_slice(&self.contacts);
        mass.clear();
        mass.extend((0..n * n).map(|e| geo.re(self.mass(e / n, e % n))));
        r.clear();
        r.extend((0..n).map(|i| self.forces.re(i)));
    }

    /// `-K_y`, the derivatives in `y = (x, u)` of the logistic and hard models' equations (the linearise
    /// stage's `system`) with a constant noise at their solution `p = [v'; lambda]`, into `out`
    /// (row-major `(n + m) x (2n + n_u)`), read off the ingredients' gradients: with `v` the step's
    /// velocities and `slope_k` row `k`'s `d phi / d w` (0 for a row held fixed),
    /// `K_i = sum_j M_ij (v'_j - v_j) - h r_i - sum_k J_ki lambda_k` and
    /// `K_(n + k) = phi(lambda_k, w_k)`, `w_k = d_k / h + sum_j J_kj v'_j`.
    pub(super) fn equations_y(&self, h: f64, v: &[f64], p: &[f64], slope: &[f64], out: &mut [f64]) {
        let (n, m, geo, forces) = (self.n, self.m, &self.geometry, &self.forces);
        let cols = out.len() / (n + m);
        out.fill(0.0);
        for i in 0..n {
            let row = &mut out[i * cols..(i + 1) * cols];
            for (e, g) in row.iter_mut().zip(forces.g(i)) {
                *e = h * g;
            }
            for j in 0..n {
                let f = self.mass(i, j);
                let s = p[j] - v[j];
                for (e, g) in row.iter_mut().zip(geo.g(f)) {
                    *e -= s * g;
                }
                row[n + j] += geo.re(f);
            }
            for k in 0..m {
                let l = p[n + k];
                for (e, g) in row.iter_mut().zip(geo.g(self.jac(k, i))) {
                    *e += l * g;
                }
            }
        }
        for &(j, y) in &self.actuated {
            out[j * cols + y] += h;
        }
        for k in 0..m {
            let s = slope[k];
            if s == 0.0 {
                continue;
            }
            let row = &mut out[(n + k) * cols..(n + k + 1) * cols];
            for (e, g) in row.iter_mut().zip(geo.g(self.dist(k))) {
                *e = -s * g / h;
            }
            for j in 0..n {
                let sv = s * p[j];
                for (e, g) in row.iter_mut().zip(geo.g(self.jac(k, j))) {
                    *e -= sv * g;
                }
            }
        }
    }

    /// The first-order ingredients over `y[first..first + 8]`.
    pub(super) fn first_order(&self, first: usize, cols: usize) -> Ingredients<D1> {
        let dirs: Vec<usize> = (first..(first + DIRECTIONS).min(cols)).collect();
        self.convert(&dirs, lift_first, |l| D1::from_re(0.0).derivative(l))
    }

    /// The ingredients lifted to second-order duals over the directions `dirs` of `y` (at most 8).
    pub(super) fn lifted(&self, dirs: &[usize]) -> Ingredients<D2> {
        self.convert(dirs, lift_second, |l| D2::from_re(0.0).derivative(l))
    }
}

/// Function `i` of `t` as a first-order dual over the directions `dirs` of `y` (`t`'s arguments are the
/// leading entries of `y`).
fn lift_first(t: &Taylor, i: usize, dirs: &[usize]) -> D1 {
    let mut grad = SVector::<f64, DIRECTIONS>::zeros();
    let g = t.g(i);
    for (l, &y) in dirs.iter().enumerate() {
        if y < t.dim {
            grad[l] = g[y];
        }
    }
    D1::new(t.re(i), Derivative::some(grad))
}

/// Function `i` of `t` as a second-order dual over the directions `dirs` of `y`.
fn lift_second(t: &Taylor, i: usize, dirs: &[usize]) -> D2 {
    let mut grad = SMatrix::<f64, 1, DIRECTIONS>::zeros();
    let mut hess = SMatrix::<f64, DIRECTIONS, DIRECTIONS>::zeros();
    let (g, dim) = (t.g(i), t.dim);
    for (l, &a) in dirs.iter().enumerate() {
        if a >= dim {
            continue;
        }
        grad[(0, l)] = g[a];
        for (l2, &b) in dirs.iter().enumerate() {
            if b < dim {
                hess[(l, l2)] = t.hessian(i, a, b);
            }
        }
    }
    D2::new(t.re(i), Derivative::some(grad), Derivative::some(hess))
}

/// A first-order jet over `y` (or a chunk of it) as the vector dual of the step's equations.
pub(super) fn jet1_dual(d: &F1) -> D1 {
    D1::new(d.re, Derivative::some(SVector::from(d.g)))
}
