//! The global policy of paper eq. (20): the stored controller whose state is nearest, under the Euclidean
//! norm scaled by the covariance of the stored states, with the free angle (theta3) compared modulo its
//! period (pi: the ellipse is symmetric), then that controller's linear law. A task's turn symmetries
//! ([`Policy::for_task`]: angles of bodies a half turn, or any turn, maps onto themselves, which the task
//! does not see) are compared modulo that turn as well.
//!
//! The distance: with `L` the Cholesky factor of the stored states' covariance and `p = L^-1 pi e_free`,
//! states are whitened (`y = L^-1 x`) and their free angle reduced to `[0, pi)` (`y - k p`, `k` whole
//! periods); a stored state is at the smallest of the three distances `|y' - w' - j p|`, `j = -1, 0, 1`.
//! The look-up is a kd-tree (`kiddo`) over the stored states, each stored three times shifted by
//! `j p`, for states of 2, 4, 6 or 8 entries (the finger: 6), and a scan of the same distances beyond:
//! at the finger's 400 controllers the tree answers in 0.25-0.4 us against the scan's 2-3 us, at 1600 in
//! 0.6 against 9 (docs/benchmarks.md).

use crate::entry::{Entry, LocalValue};
use crate::error::LibraryError;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use std::f64::consts::PI;
use std::num::NonZero;
use std::sync::OnceLock;

/// How far past the range the stored controls span ([`Policy::envelope`]) a law's control may go, as a
/// fraction of that range on either side, before [`Policy::control`] saturates it: a law near the
/// range's edge is applied as it is, one asking ten times the stored torques (a finger flipping a block,
/// docs/tasks.md) is not.
pub const SATURATION_MARGIN: f64 = 1.0;

/// The shifts, in whole periods, each stored state is kept at.
const SHIFTS: [f64; 3] = [-1.0, 0.0, 1.0];

/// The look-up structure over the reduced, whitened, shifted states (item `3 i + s`: entry `i` at shift
/// `SHIFTS[s]`).
#[derive(Debug, Clone)]
enum Index {
    K2(ImmutableKdTree<f64, 2>),
    K4(ImmutableKdTree<f64, 4>),
    K6(ImmutableKdTree<f64, 6>),
    K8(ImmutableKdTree<f64, 8>),
    K10(ImmutableKdTree<f64, 10>),
    K12(ImmutableKdTree<f64, 12>),
    /// Row-major `3 count x n`.
    Scan(Vec<f64>),
}

fn tree<const K: usize>(points: &[f64]) -> ImmutableKdTree<f64, K> {
    let rows: Vec<[f64; K]> = points
        .chunks_exact(K)
        .map(|r| std::array::from_fn(|i| r[i]))
        .collect();
    ImmutableKdTree::new_from_slice(&rows)
}

fn query<const K: usize>(tree: &ImmutableKdTree<f64, K>, y: &[f64], count: usize) -> Vec<usize> {
    let q: [f64; K] = std::array::from_fn(|i| y[i]);
    if count == 1 {
        return vec![tree.nearest_one::<SquaredEuclidean>(&q).item as usize];
    }
    let count = NonZero::new(count).unwrap_or(NonZero::<usize>::MIN);
    tree.nearest_n::<SquaredEuclidean>(&q, count)
        .into_iter()
        .map(|n| n.item as usize)
        .collect()
}

impl Index {
    fn new(points: Vec<f64>, n: usize) -> Self {
        match n {
            2 => Index::K2(tree(&points)),
            4 => Index::K4(tree(&points)),
            6 => Index::K6(tree(&points)),
            8 => Index::K8(tree(&points)),
            10 => Index::K10(tree(&points)),
            12 => Index::K12(tree(&points)),
            _ => Index::Scan(points),
        }
    }

    /// The `count` items nearest to `y`, nearest first.
    fn nearest(&self, y: &[f64], count: usize) -> Vec<usize> {
        match self {
            Index::K2(t) => query(t, y, count),
            Index::K4(t) => query(t, y, count),
            Index::K6(t) => query(t, y, count),
            Index::K8(t) => query(t, y, count),
            Index::K10(t) => query(t, y, count),
            Index::K12(t) => query(t, y, count),
            Index::Scan(points) => {
                let n = y.len();
                // The `count` smallest (distance, item) pairs so far, nearest first. Items come in
                // order, so a new one goes after the equal distances kept: equal distances by item, as a
                // scan in order finds them. No vector of every distance.
                let count = count.min(points.len() / n.max(1));
                if count == 0 {
                    return Vec::new();
                }
                let mut best: Vec<(f64, usize)> = Vec::with_capacity(count + 1);
                for (item, w) in points.chunks_exact(n).enumerate() {
                    let d: f64 = y.iter().zip(w).map(|(a, b)| (a - b) * (a - b)).sum();
                    // No nearer than the farthest kept, the common case, in one comparison.
                    if best.len() == count && best[count - 1].0.total_cmp(&d).is_le() {
                        continue;
                    }
                    let at = best.partition_point(|b| b.0.total_cmp(&d).is_le());
                    best.insert(at, (d, item));
                    best.truncate(count);
                }
                best.into_iter().map(|(_, item)| item).collect()
            }
        }
    }
}

/// A nearest-neighbour policy over stored local controllers (see the module documentation).
#[derive(Debug, Clone)]
pub struct Policy {
    n: usize,
    m: usize,
    free: usize,
    /// The free entry's period (0: no periodic entry; states compare as they are).
    period: f64,
    /// The entries compared modulo a turn ([`Policy::for_task`]).
    symmetric: Vec<Symmetric>,
    /// The shifts, in whole periods, each stored state is kept at: [`SHIFTS`], or `[0]` without a
    /// period.
    shifts: &'static [f64],
    /// Whole periods each stored state's free angle was reduced by.
    turns: Vec<f64>,
    index: Index,
    /// `L^-1 pi e_free`: the whitened shift of one period of the free angle.
    period_shift: Vec<f64>,
    /// Cholesky factor `L` of the states' covariance (row-major lower).
    chol: Vec<f64>,
    states: Vec<Vec<f64>>,
    controls: Vec<Vec<f64>>,
    gains: Vec<Vec<f64>>,
    /// The stored value models, as stored ...
    values: Vec<LocalValue>,
    /// ... and convexified ([`LocalValue::convexified`], an eigendecomposition each), when first
    /// ranked: a closed loop ranks a few of a library's thousands.
    convex: Vec<OnceLock<LocalValue>>,
    /// Stored controllers compared by their value models (1: the nearest alone, eq. 20).
    neighbours: usize,
    /// Bounds the controls are saturated to (the task's control limits), if any.
    limits: Option<ddp::ControlLimits>,
    /// Each stored controller's reach ([`Entry::reach`]) squared; infinite where unlimited.
    reach: Vec<f64>,
    /// The range of each control over the stored controllers: a law asking beyond it extrapolates.
    envelope: Vec<(f64, f64)>,
    /// The task's control weight `w` (running cost `w |u|^2` a step) the ranking charges a law for the
    /// part of its control beyond [`Self::envelope`] ([`Policy::with_control_weight`]; 0: no charge).
    control_weight: f64,
    /// The time step each stored controller was optimised at ([`Entry::time_step`]).
    time_steps: Vec<f64>,
    /// The time step the policy runs at, whose controllers it prefers ([`Policy::with_time_step`]).
    time_step: Option<f64>,
}

/// A state entry compared modulo a turn ([`Policy::for_task`]).
#[derive(Debug, Clone, Copy)]
struct Symmetric {
    entry: usize,
    /// The turn: pi, or 0 for any.
    turn: f64,
    /// The angle the stored states' are taken to within half a turn of (0 for any turn).
    centre: f64,
}

impl Symmetric {
    /// The angle `a` as the stored states have it: within half its turn of the centre, or the centre.
    fn canonical(&self, a: f64) -> f64 {
        self.centre + self.offset(a - self.centre)
    }

    /// A difference `d` of the angle as the same state sees it: within half its turn, or zero.
    fn offset(&self, d: f64) -> f64 {
        if self.turn > 0.0 {
            wrap(d, self.turn)
        } else {
            0.0
        }
    }
}

/// `x` with each of `symmetric`'s entries taken as the stored states have it.
fn canonicalise(symmetric: &[Symmetric], x: &mut [f64]) {
    for t in symmetric {
        x[t.entry] = t.canonical(x[t.entry]);
    }
}

/// `Err` unless a period is finite and positive.
fn check_period(period: f64) -> Result<(), LibraryError> {
    if period.is_finite() && period > 0.0 {
        return Ok(());
    }
    Err(LibraryError::Setting {
        name: "period",
        value: period,
        expected: "finite and positive",
    })
}

/// Whole periods `p` in `x` (rounded down; 0 without a period, `p = 0`).
fn whole_periods(x: f64, p: f64) -> f64 {
    if p > 0.0 { (x / p).floor() } else { 0.0 }
}

/// `x` wrapped into `(-p/2, p/2]`.
fn wrap(x: f64, p: f64) -> f64 {
    x - p * (x / p).round()
}

impl Policy {
    /// The policy of `entries` for a scene with `n` joints, `m` controls and the free angle at index
    /// `free` of the state (period `pi`).
    pub fn new(
        entries: &[Entry],
        n_state: usize,
        m: usize,
        free: usize,
    ) -> Result<Self, LibraryError> {
        Policy::with_period(entries, n_state, m, free, PI)
    }

    /// The policy of a task's library: modulo its periodic entry if it has one
    /// ([`task::Progress::period`]), else comparing states as they are.
    pub fn for_progress(
        entries: &[Entry],
        n_state: usize,
        m: usize,
        progress: &task::Progress,
    ) -> Result<Self, LibraryError> {
        Policy::for_task(entries, n_state, m, progress, &[])
    }

    /// [`Policy::for_progress`], comparing states modulo a turn as well in each of the state entries of
    /// `turns` (a task's [`task::Task::turn_symmetries`]: `(entry, pi)` for the angle of a body a half
    /// turn maps onto itself, `(entry, 0)` for one any turn does, a disc's, whose angle then does not
    /// count at all; angles the task does not see). The pusher's fork kicked its block over (block angle
    /// -pi, the block where it was) on 6 of the 80 kicked runs of one library, and the policy, finding no
    /// stored state near an upturned block, left it there. `Err` for an entry out of the state's range,
    /// the periodic entry itself, or a turn other than pi and 0.
    pub fn for_task(
        entries: &[Entry],
        n_state: usize,
        m: usize,
        progress: &task::Progress,
        turns: &[(usize, f64)],
    ) -> Result<Self, LibraryError> {
        if let Some(&(c, turn)) = turns.iter().find(|&&(c, turn)| {
            c >= n_state
                || (progress.period.is_some() && c == progress.coordinate)
                || !(turn == PI || turn == 0.0)
        }) {
            return Err(LibraryError::Invalid(format!(
                "turn symmetry ({c}, {turn}) of a state of {n_state} (periodic entry {:?}; a turn is pi or 0, any)",
                progress.period.map(|_| progress.coordinate)
            )));
        }
        let (free, period) = match progress.period {
            Some(p) => {
                check_period(p)?;
                (progress.coordinate, Some(p))
            }
            None => (0, None),
        };
        Policy::build(entries, n_state, m, free, period, turns)
    }

    /// [`Policy::new`] with the periodic state entry `free` of period `period` (a task's, see
    /// [`task::Progress::of_task`]).
    pub fn with_period(
        entries: &[Entry],
        n_state: usize,
        m: usize,
        free: usize,
        period: f64,
    ) -> Result<Self, LibraryError> {
        check_period(period)?;
        Policy::build(entries, n_state, m, free, Some(period), &[])
    }

    /// [`Policy::with_period`], or without a periodic entry for `None`.
    fn build(
        entries: &[Entry],
        n_state: usize,
        m: usize,
        free: usize,
        period: Option<f64>,
        turns: &[(usize, f64)],
    ) -> Result<Self, LibraryError> {
        if free >= n_state {
            return Err(LibraryError::Invalid(format!(
                "periodic state entry {free} of a state of {n_state}"
            )));
        }
        if entries.is_empty() {
            return Err(LibraryError::Invalid(
                "a library with no controllers".into(),
            ));
        }
        for (i, e) in entries.iter().enumerate() {
            let v = &e.value;
            let ok = e.x.len() == n_state
                && e.u.len() == m
                && e.gain.len() == m * n_state
                && v.gradient.len() == n_state
                && v.hessian.len() == n_state * n_state
                && e.x
                    .iter()
                    .chain(&e.u)
                    .chain(&e.gain)
                    .chain(&v.gradient)
                    .chain(&v.hessian)
                    .chain([&v.cost_to_go, &v.per_period])
                    .all(|v| v.is_finite())
                && e.time_step.is_finite()
                && e.time_step > 0.0;
            if !ok {
                return Err(LibraryError::Invalid(format!(
                    "controller {i} has the wrong sizes, a non-finite entry or a time step that is not positive"
                )));
            }
        }
        let n = n_state;
        let count = entries.len() as f64;
        // Each half-turn entry's angles doubled have a circular mean; every stored angle is taken to
        // within a quarter turn of it (the same state), so that states a half turn apart lie together. An
        // entry any turn maps onto itself is taken to 0.
        let symmetric: Vec<Symmetric> = turns
            .iter()
            .map(|&(c, turn)| {
                let (s, c2) = entries.iter().fold((0.0, 0.0), |(s, c2), e| {
                    (s + (2.0 * e.x[c]).sin(), c2 + (2.0 * e.x[c]).cos())
                });
                let centre = if turn > 0.0 { 0.5 * s.atan2(c2) } else { 0.0 };
                Symmetric {
                    entry: c,
                    turn,
                    centre,
                }
            })
            .collect();
        let states: Vec<Vec<f64>> = entries
            .iter()
            .map(|e| {
                let mut x = e.x.clone();
                canonicalise(&symmetric, &mut x);
                x
            })
            .collect();
        // The free angle's circular mean (period pi: angles doubled), then every state's free angle
        // unwrapped next to it.
        let (s, c) = states.iter().fold((0.0, 0.0), |(s, c), x| {
            let a = 2.0 * PI * x[free] / period.unwrap_or(1.0);
            (s + a.sin(), c + a.cos())
        });
        let unwrapped = |x: &[f64]| -> Vec<f64> {
            let mut y = x.to_vec();
            if let Some(period) = period {
                let centre = s.atan2(c) * period / (2.0 * PI);
                y[free] = centre + wrap(x[free] - centre, period);
            }
            y
        };
        let mut mean = vec![0.0; n];
        for x in &states {
            for (m, v) in mean.iter_mut().zip(unwrapped(x)) {
                *m += v / count;
            }
        }
        let mut cov = vec![0.0; n * n];
        for x in &states {
            let d: Vec<f64> = unwrapped(x).iter().zip(&mean).map(|(a, b)| a - b).collect();
            for i in 0..n {
                for j in 0..n {
                    cov[i * n + j] += d[i] * d[j] / count;
                }
            }
        }
        // A floor on every variance keeps the scaling defined when a coordinate never moved (a library of
        // one controller, a locked joint).
        let trace: f64 = (0..n).map(|i| cov[i * n + i]).sum();
        let floor = 1e-9 * trace.max(1e-12) + 1e-12;
        for i in 0..n {
            cov[i * n + i] += floor;
        }
        let chol = cholesky(&cov, n).ok_or_else(|| {
            LibraryError::Invalid("the states' covariance is not positive".into())
        })?;
        let (period, shifts): (f64, &'static [f64]) = match period {
            Some(p) => (p, &SHIFTS),
            None => (0.0, &[0.0]),
        };
        let mut unit = vec![0.0; n];
        unit[free] = period;
        let period_shift = forward(&chol, n, &unit);
        let turns: Vec<f64> = states
            .iter()
            .map(|x| whole_periods(x[free], period))
            .collect();
        let points = shifted_points(&chol, &period_shift, &states, &turns, shifts);
        Ok(Policy {
            n,
            m,
            free,
            period,
            symmetric,
            shifts,
            turns,
            index: Index::new(points, n),
            period_shift,
            chol,
            states,
            controls: entries.iter().map(|e| e.u.clone()).collect(),
            gains: entries.iter().map(|e| e.gain.clone()).collect(),
            values: entries.iter().map(|e| e.value.clone()).collect(),
            convex: entries.iter().map(|_| OnceLock::new()).collect(),
            neighbours: 1,
            limits: None,
            reach: entries
                .iter()
                .map(|e| e.reach.map_or(f64::INFINITY, |r| r * r))
                .collect(),
            envelope: (0..m)
                .map(|a| {
                    entries
                        .iter()
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), e| {
                            (lo.min(e.u[a]), hi.max(e.u[a]))
                        })
                })
                .collect(),
            control_weight: 0.0,
            time_steps: entries.iter().map(|e| e.time_step).collect(),
            time_step: None,
        })
    }

    /// The same policy for a world of time step `h`: among the candidates of [`Policy::select`], the
    /// controllers optimised at `h` ([`Entry::time_step`]) compete alone where there is one (a target
    /// task's growth branches for a world of another step than the library's: the same push, optimised
    /// at 0.05 s, slides pushing's block 0.13 to 0.21 short of or past its target at 0.03 s). A policy
    /// without a time step, or whose candidates at a state include none optimised at `h`, ranks them
    /// all. `Err` unless `h` is finite and positive.
    pub fn with_time_step(mut self, h: f64) -> Result<Self, LibraryError> {
        if !(h.is_finite() && h > 0.0) {
            return Err(LibraryError::Setting {
                name: "time step",
                value: h,
                expected: "finite and positive",
            });
        }
        self.time_step = Some(h);
        Ok(self)
    }

    /// Whether controller `i` was optimised at the policy's time step.
    fn at_own_step(&self, i: usize) -> bool {
        self.time_step
            .is_some_and(|h| (self.time_steps[i] - h).abs() <= 1e-9 * h)
    }

    /// The same policy with its controls saturated to `limits` (a task's control limits: the linear law
    /// `u + K (x - x_i)` far from the stored state can ask for more than the actuators the trajectories
    /// were optimised under give). `Err` unless the bounds have the controls' size with lower <= upper.
    pub fn with_limits(mut self, limits: Option<ddp::ControlLimits>) -> Result<Self, LibraryError> {
        if let Some(l) = &limits
            && (l.lower.len() != self.m
                || l.upper.len() != self.m
                || l.lower
                    .iter()
                    .zip(&l.upper)
                    .any(|(a, b)| a.is_nan() || b.is_nan() || a > b))
        {
            return Err(LibraryError::Invalid(format!(
                "control limits for {} controls: {} lower and {} upper bounds, each lower at most its upper",
                self.m,
                l.lower.len(),
                l.upper.len()
            )));
        }
        self.limits = limits;
        Ok(self)
    }

    /// The same policy choosing, among the `neighbours` stored states nearest to the query, the
    /// controller whose local value model predicts the lowest cost-to-go there (1: the nearest, eq. 20).
    pub fn with_neighbours(mut self, neighbours: usize) -> Result<Self, LibraryError> {
        if neighbours == 0 {
            return Err(LibraryError::Setting {
                name: "neighbours",
                value: 0.0,
                expected: "at least 1",
            });
        }
        self.neighbours = neighbours;
        Ok(self)
    }

    /// The same policy charging each law it ranks for the controls it asks beyond the range the stored
    /// controllers use (per control, [`Policy::envelope`]): `w` times the squared excess, `w` the task's
    /// control weight. A linear law far from its state can ask for controls no trajectory used (a
    /// near-singular expansion's gain of 4e4 asked 1e4 of the three-link finger, whose trajectories use
    /// a few tens); its value model, linear in the state, does not see that cost. Within the range
    /// nothing changes. `Err` unless `w` is finite and at least zero.
    pub fn with_control_weight(mut self, w: f64) -> Result<Self, LibraryError> {
        if !(w.is_finite() && w >= 0.0) {
            return Err(LibraryError::Setting {
                name: "control_weight",
                value: w,
                expected: "finite and at least zero",
            });
        }
        self.control_weight = w;
        Ok(self)
    }

    /// The range `(lowest, highest)` of each control over the stored controllers.
    pub fn envelope(&self) -> &[(f64, f64)] {
        &self.envelope
    }

    /// Limit stored controller `i` to states within whitened distance `radius` of its own (see
    /// [`Entry::reach`]; the caller keeps the entry's copy in step). `Err` for an index out of range or
    /// a radius that is negative or NaN.
    pub fn set_reach(&mut self, i: usize, radius: f64) -> Result<(), LibraryError> {
        if i >= self.reach.len() || radius.is_nan() || radius < 0.0 {
            return Err(LibraryError::Invalid(format!(
                "reach {radius} for controller {i} of {}",
                self.reach.len()
            )));
        }
        self.reach[i] = radius * radius;
        Ok(())
    }

    /// How many nearest controllers the policy compares.
    pub fn neighbours(&self) -> usize {
        self.neighbours
    }

    /// Number of stored controllers.
    pub fn len(&self) -> usize {
        self.states.len()
    }

    /// Whether there are none (never: [`Policy::new`] refuses an empty library).
    pub fn is_empty(&self) -> bool {
        self.states.is_empty()
    }

    /// The stored states (each symmetric entry taken as [`Policy::for_task`] says, the same states).
    pub fn states(&self) -> &[Vec<f64>] {
        &self.states
    }

    /// The same policy answering by a scan of every stored state instead of the kd-tree (the same
    /// distances; for comparisons and tests).
    pub fn scanning(mut self) -> Self {
        if !matches!(self.index, Index::Scan(_)) {
            self.index = Index::Scan(shifted_points(
                &self.chol,
                &self.period_shift,
                &self.states,
                &self.turns,
                self.shifts,
            ));
        }
        self
    }

    /// Index of the nearest stored state to `x` and the whole periods of the free angle between them.
    pub fn nearest(&self, x: &[f64]) -> Result<(usize, f64), LibraryError> {
        Ok(self.nearest_n(x, 1)?[0])
    }

    /// The `count` nearest stored states to `x` (nearest first), each with the whole periods of the free
    /// angle between it and `x`.
    pub fn nearest_n(&self, x: &[f64], count: usize) -> Result<Vec<(usize, f64)>, LibraryError> {
        crate::check("x", x, self.n)?;
        let k = whole_periods(x[self.free], self.period);
        let mut y = forward(&self.chol, self.n, &self.canonical(x));
        for (y, p) in y.iter_mut().zip(&self.period_shift) {
            *y -= k * p;
        }
        Ok(self
            .index
            .nearest(&y, count.max(1))
            .into_iter()
            .map(|item| {
                let (i, s) = (item / self.shifts.len(), item % self.shifts.len());
                // The stored point is w_i - (k_i - j) p and the query y - k p: x is k - k_i + j periods
                // on.
                (i, k - self.turns[i] + self.shifts[s])
            })
            .collect())
    }

    /// The whitened distance from stored state `i` to `x`, `turns` whole periods of the free angle on:
    /// the distance the policy's nearest neighbours are ranked by.
    pub fn distance(&self, x: &[f64], i: usize, turns: f64) -> Result<f64, LibraryError> {
        crate::check("x", x, self.n)?;
        if i >= self.states.len() {
            return Err(LibraryError::Invalid(format!(
                "controller {i} of {}",
                self.states.len()
            )));
        }
        let mut d = vec![0.0; self.n];
        self.offset(x, i, turns, &mut d);
        Ok(self.whitened_squared(&d).sqrt())
    }

    /// `|L^-1 d|^2`.
    fn whitened_squared(&self, d: &[f64]) -> f64 {
        forward(&self.chol, self.n, d).iter().map(|y| y * y).sum()
    }

    /// `w` times the squared excess of controller `i`'s law at offset `d` beyond [`Self::envelope`].
    fn extrapolation_charge(&self, i: usize, d: &[f64]) -> f64 {
        if self.control_weight == 0.0 {
            return 0.0;
        }
        let excess: f64 = (self.envelope.iter().enumerate())
            .map(|(a, (lo, hi))| {
                let law = self.law(i, a, d);
                let e = (law - hi).max(lo - law).max(0.0);
                e * e
            })
            .sum();
        self.control_weight * excess
    }

    /// Control `a` of controller `i`'s law at offset `d`: `u_i + K_i d`, unsaturated.
    fn law(&self, i: usize, a: usize, d: &[f64]) -> f64 {
        let row = &self.gains[i][a * self.n..(a + 1) * self.n];
        row.iter()
            .zip(d)
            .fold(self.controls[i][a], |s, (k, d)| s + k * d)
    }

    /// `x - x_i` with the free angle taken `turns` whole periods back and each symmetric entry's
    /// difference within a quarter turn (a half turn's) or zero (any turn's), into `d`.
    fn offset(&self, x: &[f64], i: usize, turns: f64, d: &mut [f64]) {
        for ((d, a), b) in d.iter_mut().zip(x).zip(&self.states[i]) {
            *d = a - b;
        }
        d[self.free] -= turns * self.period;
        for t in &self.symmetric {
            d[t.entry] = t.offset(d[t.entry]);
        }
    }

    /// `x` with each symmetric entry taken as the stored states' are (the same state; `x` itself
    /// without symmetric entries).
    fn canonical<'x>(&self, x: &'x [f64]) -> std::borrow::Cow<'x, [f64]> {
        if self.symmetric.is_empty() {
            return std::borrow::Cow::Borrowed(x);
        }
        let mut y = x.to_vec();
        canonicalise(&self.symmetric, &mut y);
        std::borrow::Cow::Owned(y)
    }

    /// The state entries compared modulo a turn and each one's turn (pi, or 0 for any;
    /// [`Policy::for_task`]).
    pub fn turn_symmetries(&self) -> Vec<(usize, f64)> {
        self.symmetric.iter().map(|t| (t.entry, t.turn)).collect()
    }

    /// The stored controller the policy uses at `x` and the whole periods between them: the nearest
    /// (eq. 20), or among the [`Policy::neighbours`] nearest the one whose local value model predicts
    /// the lowest cost-to-go at `x` (ties to the nearer). The models are ranked convexified
    /// ([`LocalValue::convexified`]), so that none wins by extrapolating negative curvature, plus the
    /// charge for controls beyond the stored range ([`Policy::with_control_weight`]); a controller
    /// whose reach ([`Entry::reach`]) ends short of `x` is passed over while one of the candidates
    /// reaches it (else they all compete).
    pub fn select(&self, x: &[f64]) -> Result<(usize, f64), LibraryError> {
        Ok(self.choose(x)?.0)
    }

    /// [`Policy::select`] and the offset of `x` from the chosen state.
    fn choose(&self, x: &[f64]) -> Result<((usize, f64), Vec<f64>), LibraryError> {
        let mut candidates = self.nearest_n(x, self.neighbours)?;
        if candidates.iter().any(|&(i, _)| self.at_own_step(i)) {
            candidates.retain(|&(i, _)| self.at_own_step(i));
        }
        let mut d = vec![0.0; self.n];
        let mut best = (f64::INFINITY, candidates[0]);
        if candidates.len() > 1 {
            // The best within reach, and the best of all for when none reaches `x`.
            let mut best_within = (f64::INFINITY, None);
            for &(i, turns) in &candidates {
                self.offset(x, i, turns, &mut d);
                let v = self.convex[i]
                    .get_or_init(|| self.values[i].convexified())
                    .predict(&d, turns)
                    + self.extrapolation_charge(i, &d);
                if v < best.0 {
                    best = (v, (i, turns));
                }
                let within =
                    self.reach[i].is_infinite() || self.whitened_squared(&d) <= self.reach[i];
                if within && v < best_within.0 {
                    best_within = (v, Some((i, turns)));
                }
            }
            if let (v, Some(c)) = best_within {
                best = (v, c);
            }
        }
        let (i, turns) = best.1;
        self.offset(x, i, turns, &mut d);
        Ok(((i, turns), d))
    }

    /// The policy's control at `x` (eq. 20, or the value-ranked choice of [`Policy::select`]) written
    /// into `u`, saturated near [`Policy::envelope`] (widened by [`SATURATION_MARGIN`] times its width on
    /// either side: no stored trajectory asked for more, and far beyond it a linear law only
    /// extrapolates, as a finger flipping a block did that asked for ten times its stored torques and
    /// flung the block) and then to the control limits; returns the controller used.
    pub fn control(&self, x: &[f64], u: &mut [f64]) -> Result<usize, LibraryError> {
        let ((i, _), d) = self.choose(x)?;
        if u.len() != self.m {
            return Err(LibraryError::Input {
                what: "u",
                problem: format!("has {} entries, expected {}", u.len(), self.m),
            });
        }
        for (a, u) in u.iter_mut().enumerate() {
            let (lo, hi) = self.envelope[a];
            let margin = SATURATION_MARGIN * (hi - lo);
            *u = self.law(i, a, &d).clamp(lo - margin, hi + margin);
            if let Some(l) = &self.limits {
                *u = u.clamp(l.lower[a], l.upper[a]);
            }
        }
        Ok(i)
    }
}

/// The stored states whitened, reduced by their whole periods `turns` and shifted by each of [`SHIFTS`]
/// (row-major `3 count x n`, item `3 i + s`).
fn shifted_points(
    chol: &[f64],
    period_shift: &[f64],
    states: &[Vec<f64>],
    turns: &[f64],
    shifts: &[f64],
) -> Vec<f64> {
    let n = period_shift.len();
    let mut points = Vec::with_capacity(shifts.len() * states.len() * n);
    for (x, k) in states.iter().zip(turns) {
        let w = forward(chol, n, x);
        for &j in shifts {
            points.extend(w.iter().zip(period_shift).map(|(w, p)| w - (k - j) * p));
        }
    }
    points
}

fn cholesky(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= l[i * n + k] * l[j * n + k];
            }
            if i == j {
                if !(s > 0.0 && s.is_finite()) {
                    return None;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    Some(l)
}

/// `L^-1 b` for lower-triangular `L`.
fn forward(l: &[f64], n: usize, b: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; n];
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i * n + k] * y[k];
        }
        y[i] = s / l[i * n + i];
    }
    y
}
