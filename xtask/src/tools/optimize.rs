//! `cargo xtask optimize`: iLQG / DDP on a task of a scene file (the built-in scenes/finger.toml's `spin`,
//! the paper's, by default) or on the unicycle benchmark, one line per pass behind a progress bar, the
//! trajectory and its linear policy as JSON.

use crate::tools::Num;
use crate::tools::step::SimArgs;
use anyhow::Context;
use ddp::problems::Unicycle;
use ddp::{ControlLimits, Ddp, DdpSettings, Iteration, Method, Regularisation, Solution};
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;
use task::SceneDynamics;

/// Which problem.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Problem {
    /// A task of a scene file (--scene, --task; the built-in scenes/finger.toml's `spin` is the flicking
    /// finger of SCENE.md, cost -theta3 + 0.05 |u|^2).
    #[value(alias = "finger")]
    Task,
    /// The unicycle benchmark: x0 = [-1, -1, 1], dt = 0.1, T = 75, 50|x|^2 + 0.5|u|^2, final 50|x|^2.
    Unicycle,
}

/// Which backward pass.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum MethodArg {
    /// Full second-order DDP (the dynamics' Hessians of V_x . f). Its second derivatives are kept per
    /// knot: a problem that would need more than 8 GiB of them over the horizon (a scene of tens of free
    /// bodies) is refused with the estimate before anything is allocated; use ilqr there.
    Full,
    /// Gauss-Newton iLQR.
    Ilqr,
}

/// Where the regularisation goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum RegArg {
    /// mu on the value Hessian (Q_uu + mu f_u^T f_u).
    State,
    /// mu on the controls (Q_uu + mu I).
    Control,
}

/// Options of `cargo xtask optimize`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Problem to solve.
    #[arg(long, value_enum, default_value = "task")]
    problem: Problem,
    /// Simulator options (scene files only).
    #[command(flatten)]
    sim: SimArgs,
    /// A task of the scene file (its `[task.NAME]` table; the file's only one by default, the built-in
    /// finger's `spin`): its cost, initial state, time step, horizon, contact model and control limits; a
    /// flag given on the command line overrides the task's value.
    #[arg(long)]
    task: Option<String>,
    /// Horizon N (1 to 100000) [default: the task's, or 75 for the unicycle].
    #[arg(long,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=100_000))]
    horizon: Option<usize>,
    /// Passes at most (1 to 100000).
    #[arg(long, default_value_t = 300,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=100_000))]
    iterations: usize,
    /// Backward pass.
    #[arg(long, value_enum, default_value = "full")]
    method: MethodArg,
    /// Regularisation [default: state; with full DDP, a task's solve that stops without converging is then
    /// continued under the control one, and kept where cheaper: docs/tasks.md, "A first solve that crawls"].
    /// Given, the solve keeps to it.
    #[arg(long, value_enum)]
    regularisation: Option<RegArg>,
    /// Start each line search near the last accepted step size.
    #[arg(long)]
    adaptive_line_search: bool,
    /// Threads the knots of each pass are differentiated on (1 to 256; the same solution on any number).
    #[arg(long, default_value_t = 1,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=256))]
    threads: usize,
    /// Box every control to [-L, L].
    #[arg(long)]
    limit: Option<f64>,
    /// Initial state (comma-separated; default: the task's or the unicycle's [-1, -1, 1]).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    x0: Option<Vec<f64>>,
    /// Write the trajectory, its policy and the passes as JSON here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// No per-pass lines.
    #[arg(long)]
    quiet: bool,
    /// Exit with status 1 unless the optimiser converged (CostConverged or StepConverged) and, for a
    /// scene's task, its trajectory felt a contact.
    #[arg(long)]
    strict: bool,
    /// For a scene's task: when the solve never feels a contact, do not reach for it (pulling each
    /// needed pair together, then, on a smoothed model, continuing in the noise scale: doubling sigma
    /// until the contact is felt, then halving it back, each solve warm-started from the last); just say
    /// so.
    #[arg(long)]
    no_continuation: bool,
}

/// What a status means, for the summary line.
fn meaning(status: ddp::Status) -> &'static str {
    match status {
        ddp::Status::CostConverged => {
            "converged: the last accepted pass changed the cost by less than the tolerance"
        }
        ddp::Status::StepConverged => "converged: the feedforward step fell below the tolerance",
        ddp::Status::MaxIterations => "not converged: the pass limit (--iterations) was reached",
        ddp::Status::NoDescent => {
            "not converged: no step size reduced the cost up to the largest regularisation"
        }
        ddp::Status::RegularisationExceeded => {
            "not converged: Q_uu stayed indefinite up to the largest regularisation"
        }
    }
}

#[derive(Serialize)]
struct Report<'a> {
    problem: String,
    method: String,
    passes: usize,
    status: String,
    cost: f64,
    seconds: f64,
    solution: &'a Solution,
}

/// The optimiser's settings from the command line (and a task's control limits unless `--limit` is
/// given).
fn settings(args: &Args, m: usize, task: Option<&task::Task>) -> DdpSettings {
    DdpSettings {
        method: match args.method {
            MethodArg::Full => Method::Full,
            MethodArg::Ilqr => Method::GaussNewton,
        },
        regularisation: match args.regularisation.unwrap_or(RegArg::State) {
            RegArg::State => Regularisation::State,
            RegArg::Control => Regularisation::Control,
        },
        max_iterations: args.iterations,
        adaptive_line_search: args.adaptive_line_search,
        control_limits: match args.limit {
            Some(l) => Some(ControlLimits {
                lower: vec![-l; m],
                upper: vec![l; m],
            }),
            None => task.and_then(|t| t.control_limits.clone()),
        },
        threads: args.threads,
        ..DdpSettings::default()
    }
}

/// Run `cargo xtask optimize`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let bar = ProgressBar::new(args.iterations as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} passes  cost {msg}")
            .expect("a valid template"),
    );
    let quiet = args.quiet;
    let mut pass = 0usize;
    let observe = |it: &Iteration| {
        pass += 1;
        bar.inc(1);
        bar.set_message(Num(it.cost, 9).to_string());
        if !quiet {
            let cost = Num(it.cost, 12).to_string();
            let line = format!(
                "pass {pass:4}  cost {cost:>18}  reduction {:>10.3e}  expected {:>10.3e}  mu {:>9.2e}  alpha {:>6.4}  step {:>9.2e}",
                it.reduction, it.expected, it.mu, it.alpha, it.step
            );
            if bar.is_hidden() {
                println!("{line}");
            } else {
                bar.println(line);
            }
        }
    };
    let start = Instant::now();
    let horizon = args.horizon.unwrap_or(75);
    // What a task's terms say of the solution.
    let mut summary = None;
    // With a task: what the contact check said, when it found none felt at first.
    let mut felt_note: Option<String> = None;
    let mut never_felt = false;
    let (solution, problem) = match args.problem {
        Problem::Task => {
            let file = args.sim.problem_file()?;
            let task = file.task(args.task.as_deref())?;
            let sim = args.sim.simulator_of(file.scene.clone(), Some(&task))?;
            let m = file.scene.n_controls;
            let x0 = args.x0.clone().unwrap_or_else(|| task.x0.clone());
            if args.x0.is_some() {
                crate::tools::step::warn_of_overlap(&file.scene, &x0);
            }
            let horizon = args.horizon.unwrap_or(task.horizon);
            println!(
                "task {}: h = {}, N = {horizon}, {}, x0 = {x0:?}",
                task.name,
                sim.settings().h,
                sim.settings().model
            );
            let ddp = Ddp::new(settings(args, m, Some(&task)))?;
            let base = *sim.settings();
            let mut probe = dynamics::Simulator::new(file.scene.clone(), base)?;
            let sol = ddp.solve_observed(
                &SceneDynamics::new(sim),
                &task.cost,
                &x0,
                &vec![vec![0.0; m]; horizon],
                observe,
            )?;
            let problem = task::ContactProblem {
                ddp: &ddp,
                scene: &file.scene,
                settings: &base,
                cost: &task.cost,
                x0: &x0,
            };
            let felt = task::contact_felt(&mut probe, &task.cost, &x0, &sol.controls)?;
            if !felt {
                println!(
                    "no contact felt: the solve on the task's model ({}) never touches (the contact's \
                     gradient is zero out of reach)",
                    base.model
                );
            }
            // The contact searched for, a progress task's stalled plan explored, and a full-DDP solve
            // under the default regularisation that stopped without converging continued under the other
            // one, as a library's first solve is finished; a method or regularisation asked for is kept to.
            let stages = task::Stages {
                search: !args.no_continuation,
                explore: !args.no_continuation,
                other_regularisation: args.regularisation.is_none()
                    && args.method == MethodArg::Full,
            };
            let progress = task::Progress::of_task(&task)?;
            let before = sol.cost;
            let finished = problem.finish(sol, &progress, stages, |s, stage, felt| {
                println!(
                    "continuation: sigma {}: {} after {} passes, cost {}{}",
                    Num(s, 4),
                    stage.status,
                    stage.iterations.len(),
                    Num(stage.cost, 6),
                    match felt {
                        Some(true) => ", contact felt",
                        Some(false) => ", contact not felt",
                        None => "",
                    }
                );
            })?;
            let mut note = None;
            if let Some(search) = finished.search.as_ref().filter(|_| !felt) {
                let reach = search.reach.as_ref();
                for pull in reach.map_or(&[][..], |r| &r.tries[..]) {
                    let name = pair_name(&file.scene, pull.pair);
                    match pull.task_cost {
                        Some(cost) => println!(
                            "reach: {name} pulled together ({} passes, cost {}), then the task's own \
                             solve: cost {}, contact {}",
                            pull.passes,
                            Num(pull.cost, 6),
                            Num(cost, 6),
                            if pull.felt {
                                "felt"
                            } else {
                                "not felt, or no cheaper"
                            }
                        ),
                        None => println!(
                            "reach: {name} pulled ({} passes, cost {}), but not into contact: no task \
                             solve from there",
                            pull.passes,
                            Num(pull.cost, 6)
                        ),
                    }
                }
                // The task's noise scale (a continuation ran only for a smoothed model).
                let sigma = task::noise_scale(base.model).unwrap_or(0.0);
                let pairs = |ps: &[usize]| {
                    ps.iter()
                        .map(|&p| pair_name(&file.scene, p))
                        .collect::<Vec<_>>()
                        .join(", ")
                };
                note = Some(match search.outcome() {
                    task::ContactOutcome::Felt => "contact felt".to_string(),
                    task::ContactOutcome::OutOfReach(o) => format!(
                        "no contact felt, and none in reach: {} stays apart over the horizon by \
                         more than twice the driven body's reach (by {} at its nearest), so no \
                         pull or continuation was tried; the solve is kept",
                        pair_name(&file.scene, o.pair),
                        Num(o.clearance, 3)
                    ),
                    task::ContactOutcome::Pulled(p) => format!(
                        "reached the contact by pulling {} together, then solved the task's own cost",
                        pair_name(&file.scene, p)
                    ),
                    task::ContactOutcome::TouchedNotKept(touched) => format!(
                        "no contact kept: the controls can reach it (pulling {} together touched), \
                         but the task's own solve from there let go again or cost more than the \
                         solve that never touches (cost {}), which is kept: no solve found through \
                         the contact pays by the task's cost from this start",
                        pairs(&touched),
                        Num(search.solution.cost, 6)
                    ),
                    task::ContactOutcome::Continued(top) => format!(
                        "continued in the noise scale: contact felt at sigma {}, solved back \
                         down to {}",
                        Num(top, 4),
                        Num(sigma, 4)
                    ),
                    task::ContactOutcome::Lost(top) => format!(
                        "no contact felt: found at sigma {}, and lost again (or no cheaper \
                         than the solve at {}) on the way back down; that solve is kept",
                        Num(top, 4),
                        Num(sigma, 4)
                    ),
                    task::ContactOutcome::NeverFelt => format!(
                        "no contact felt even at sigma {} ({}x the task's): nothing the controls \
                         do reaches a contact within the horizon; the solve at the task's is kept",
                        Num(sigma * (1 << task::CONTINUATION_DOUBLINGS) as f64, 4),
                        1 << task::CONTINUATION_DOUBLINGS
                    ),
                    task::ContactOutcome::NoContinuation => {
                        "no contact felt: no pull found a cheaper solve that feels it, and the \
                         hard model has no action at a distance to continue from (--model \
                         logistic can feel it)"
                            .to_string()
                    }
                });
            } else if !felt {
                note = Some("no contact felt (--no-continuation)".to_string());
            }
            if let Some(explored) = finished.explored.as_ref().filter(|e| e.tried > 0) {
                let outcome = if explored.kept {
                    format!(
                        "the cheapest that does not stall is kept, cost {}",
                        Num(explored.solution.cost, 6)
                    )
                } else {
                    "none that does not stall costs less; the solve is kept".to_string()
                };
                let before = finished.search.as_ref().map_or(before, |s| s.solution.cost);
                println!(
                    "explored: the solve (cost {}) advances less than {} the rewarded way, so it \
                     was solved again from {} smooth random starts: {outcome}",
                    Num(before, 6),
                    task::STALL_ADVANCE,
                    explored.tried,
                );
            }
            if let Some(other) = finished.other.as_ref().filter(|o| o.tried) {
                let (name, form) = match other.regularisation {
                    ddp::Regularisation::State => ("state", "Q_uu + mu f_u^T f_u"),
                    ddp::Regularisation::Control => ("control", "Q_uu + mu I"),
                };
                println!(
                    "continued under the {name} regularisation ({form}), the solve stopping \
                     unconverged: cost {} after {} passes, {}",
                    Num(other.cost, 6),
                    other.passes,
                    if other.kept {
                        "cheaper: kept"
                    } else {
                        "no cheaper: the solve above is kept"
                    }
                );
            }
            never_felt = !finished.felt;
            let sol = finished.solution;
            if let Some(note) = &note {
                println!("{note}");
            }
            felt_note = note;
            summary = Some(task_summary(&file.scene, &task, &sol.states));
            (sol, format!("task {}", task.name))
        }
        Problem::Unicycle => {
            anyhow::ensure!(
                args.task.is_none(),
                "--task belongs to scene files; the unicycle has none"
            );
            let x0 = args.x0.clone().unwrap_or_else(|| Unicycle::X0.to_vec());
            let ddp = Ddp::new(settings(args, 2, None))?;
            let sol = ddp.solve_observed(
                &Unicycle { dt: 0.1 },
                &Unicycle::benchmark_cost(),
                &x0,
                &vec![vec![0.0; 2]; horizon],
                observe,
            )?;
            (sol, "unicycle".to_string())
        }
    };
    let seconds = start.elapsed().as_secs_f64();
    bar.finish_and_clear();
    let method = format!("{:?}", args.method).to_lowercase();
    println!(
        "{problem} ({method}): {} after {} passes, cost {:.12e}, {:.1} ms",
        solution.status,
        solution.iterations.len(),
        solution.cost,
        seconds * 1e3
    );
    if never_felt {
        // Converged or not, a solve that never touches has optimised nothing through the contact.
        println!(
            "status: no contact felt, nothing moved through a contact (the optimiser: {})",
            meaning(solution.status)
        );
    } else {
        println!("status: {}", meaning(solution.status));
    }
    let gain = solution
        .gains
        .iter()
        .flatten()
        .fold(0.0f64, |a, k| a.max(k.abs()));
    match &summary {
        Some(summary) => println!("{summary}; largest feedback gain |K| {gain:.3e}"),
        None => println!("largest feedback gain |K| {gain:.3e}"),
    }
    if let Some(path) = &args.out {
        let report = Report {
            problem,
            method,
            passes: solution.iterations.len(),
            status: format!("{:?}", solution.status),
            cost: solution.cost,
            seconds,
            solution: &solution,
        };
        crate::write_file(path, serde_json::to_string(&report)?)
            .with_context(|| format!("writing {}", path.display()))?;
        println!("wrote {}", path.display());
    }
    if args.strict && !solution.status.converged() {
        anyhow::bail!("--strict: {}", meaning(solution.status));
    }
    if args.strict && never_felt {
        anyhow::bail!("--strict: {}", felt_note.unwrap_or_default());
    }
    Ok(())
}

/// Each state entry a task's terms weigh, from the first state to the last (with the target of a
/// quadratic term), one line: `block.x 0.000 -> 0.584 (target 0.6)`.
fn task_summary(scene: &dynamics::Scene, task: &task::Task, states: &[Vec<f64>]) -> String {
    let names = scene.state_names();
    let (first, last) = (&states[0], states.last().expect("N + 1 states"));
    let mut seen: Vec<(usize, Option<f64>)> = Vec::new();
    for t in task.cost.running.iter().chain(&task.cost.final_terms) {
        let key = (t.index, (t.quadratic != 0.0).then_some(t.target));
        if !seen.contains(&key) {
            seen.push(key);
        }
    }
    let parts: Vec<String> = seen
        .into_iter()
        .map(|(i, target)| {
            let target = target.map_or(String::new(), |t| format!(" (target {t})"));
            format!(
                "{} {} -> {}{target}",
                names[i],
                crate::tools::Num(first[i], 4),
                crate::tools::Num(last[i], 4)
            )
        })
        .collect();
    format!("over the horizon: {}", parts.join("; "))
}

/// A contact pair as `a-b`, by its bodies' names.
fn pair_name(scene: &dynamics::Scene, pair: usize) -> String {
    scene
        .pair_name(pair)
        .unwrap_or_else(|| format!("contact pair {pair}"))
}
