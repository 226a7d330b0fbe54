//! `cargo xtask view`: the interactive viewer on 127.0.0.1.

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use library::{Library, LibrarySettings};
use std::net::{Ipv4Addr, SocketAddr};
use std::path::PathBuf;
use viewer::protocol::PolicyKind;
use viewer::{Viewer, ViewerConfig, WorldSettings};

/// Options of `cargo xtask view`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The library for the library policy. Default, for the finger: results/finger.lib (written by
    /// `cargo xtask train` and `cargo xtask reproduce` with their default settings) if it exists, else
    /// that library built now in memory (about 20-30 s; not saved: view writes no file); for another
    /// --scene: none (online MPC).
    #[arg(long)]
    library: Option<PathBuf>,
    /// Scene file (TOML) [default: the --library's scene, else the built-in scenes/finger.toml].
    #[arg(long)]
    scene: Option<PathBuf>,
    /// A task of the scene file (`[task.NAME]`): the online optimiser minimises its cost under its
    /// control limits from its initial state, at its time step and noise scale, and the page follows
    /// its progress or target [default: the --library's task, else the scene file's only task; the
    /// built-in scenes/finger.toml's is `spin`].
    #[arg(long)]
    task: Option<String>,
    /// Port on 127.0.0.1 (0: any free port).
    #[arg(long, default_value_t = 8080)]
    port: u16,
    /// The controller at start [default: library when there is one, else mpc].
    #[arg(long, value_enum)]
    policy: Option<Policy>,
    /// Optimiser passes per control step of the online MPC (1 to 100).
    #[arg(long, default_value_t = WorldSettings::default().mpc_passes,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=viewer::MAX_MPC_PASSES as u64))]
    mpc_passes: usize,
    /// Horizon of the online MPC, steps (1 to 2000).
    #[arg(long, default_value_t = WorldSettings::default().mpc_horizon,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=viewer::MAX_MPC_HORIZON as u64))]
    mpc_horizon: usize,
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum Policy {
    Library,
    Mpc,
    Off,
}

const DEFAULT_LIBRARY: &str = "results/finger.lib";

fn library(args: &Args) -> anyhow::Result<Library> {
    if let Some(path) = &args.library {
        return Library::load(path).with_context(|| format!("loading {}", path.display()));
    }
    let path = PathBuf::from(DEFAULT_LIBRARY);
    if path.exists() {
        match Library::load(&path) {
            Ok(lib) => return Ok(lib),
            // Written by another version of this project: the default library is built below.
            Err(library::LibraryError::Version { found, expected }) => println!(
                "{} has format version {found}, this build reads {expected}: building the default \
                 library in memory instead (`cargo xtask train` writes it anew)",
                path.display()
            ),
            Err(e) => {
                return Err(anyhow::Error::new(e).context(format!(
                    "loading {} (remove it or pass --library to use another)",
                    path.display()
                )));
            }
        }
    }
    let (file, task) = (
        task::ProblemFile::builtin(),
        task::ProblemFile::builtin_task().1,
    );
    let settings = LibrarySettings::default().for_task(&task);
    println!(
        "building the default library in memory, as `cargo xtask train` does (not saved: \
         `cargo xtask train` writes {DEFAULT_LIBRARY}, which view then loads) ..."
    );
    let bar = ProgressBar::new(settings.trajectories as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} trajectories  {elapsed_precise}")
            .expect("a valid template"),
    );
    let lib = Library::build(&file, Some(&task.name), &settings, |_, _| bar.inc(1))?;
    bar.finish_and_clear();
    Ok(lib)
}

/// The scene, task, library and world settings `args` ask for.
fn config(args: &Args) -> anyhow::Result<ViewerConfig> {
    let problem = match &args.scene {
        Some(path) => Some(
            task::ProblemFile::load(path).with_context(|| format!("scene {}", path.display()))?,
        ),
        None => None,
    };
    // The finger's default library only when neither a scene nor a library is named.
    let library = match (&args.library, &problem) {
        (Some(_), _) | (None, None) => Some(library(args)?),
        (None, Some(_)) => None,
    };
    let scene = match (&problem, &library) {
        (Some(p), _) => p.scene.clone(),
        (None, Some(lib)) => lib.scene().clone(),
        (None, None) => task::ProblemFile::builtin().scene,
    };
    // The task named in the scene file (the built-in file's without --scene), else the library's, else
    // the scene file's only task.
    let task = match (&args.task, &problem, &library) {
        (Some(name), Some(p), _) => p.task(Some(name))?,
        (Some(name), None, _) => task::ProblemFile::builtin().task(Some(name))?,
        (None, _, Some(lib)) => lib.task().clone(),
        (None, Some(p), None) => p.task(None)?,
        (None, None, None) => task::ProblemFile::builtin_task().1,
    };
    if let Some(lib) = &library {
        lib.check_scene(&scene)
            .context("the --library was built for another scene")?;
    }
    let defaults = WorldSettings::default();
    let (x0, h, sigma, world) = (
        match (&args.task, &library) {
            (None, Some(lib)) => lib.x0().to_vec(),
            _ => task.x0.clone(),
        },
        task.h,
        match task.model {
            task::ContactModel::Logistic(s) | task::ContactModel::Normal(s) => s,
            task::ContactModel::Hard => defaults.sigma,
        },
        if task.model == task::ContactModel::Hard {
            viewer::protocol::WorldKind::Hard
        } else {
            viewer::protocol::WorldKind::Smoothed
        },
    );
    let policy = match args.policy {
        Some(Policy::Library) => PolicyKind::Library,
        Some(Policy::Mpc) => PolicyKind::Mpc,
        Some(Policy::Off) => PolicyKind::Off,
        None if library.is_some() => PolicyKind::Library,
        None => PolicyKind::Mpc,
    };
    Ok(ViewerConfig {
        addr: SocketAddr::from((Ipv4Addr::LOCALHOST, args.port)),
        scene,
        library,
        world: WorldSettings {
            policy,
            mpc_passes: args.mpc_passes,
            mpc_horizon: args.mpc_horizon,
            x0,
            h,
            sigma,
            world,
            task,
            ..defaults
        },
    })
}

/// Run `cargo xtask view`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    let config = config(args)?;
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    runtime.block_on(async {
        let viewer = Viewer::bind(config).await?;
        println!(
            "viewer on http://{} (Ctrl-C stops it; over SSH: ssh -L {port}:127.0.0.1:{port} HOST)",
            viewer.local_addr()?,
            port = viewer.local_addr()?.port()
        );
        viewer
            .run(async {
                let _ = tokio::signal::ctrl_c().await;
            })
            .await?;
        anyhow::Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(scene: Option<&str>, task: Option<&str>, policy: Option<Policy>) -> Args {
        Args {
            library: None,
            scene: scene.map(|s| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join(s)),
            task: task.map(str::to_string),
            port: 0,
            policy,
            mpc_passes: 1,
            mpc_horizon: 60,
        }
    }

    #[test]
    fn a_scene_files_task_sets_the_world_and_online_mpc_runs_it_without_a_library() {
        let c = config(&args(Some("scenes/pushing.toml"), Some("push"), None)).unwrap();
        assert!(c.library.is_none());
        assert_eq!(c.scene.n_dof(), 5);
        let task = &c.world.task;
        assert_eq!(task.name, "push");
        assert_eq!(c.world.x0, task.x0);
        assert_eq!((c.world.h, c.world.sigma), (0.05, 0.05));
        assert_eq!(c.world.policy, PolicyKind::Mpc);
        // And the world it configures starts.
        viewer::World::new(c.scene, c.library, c.world).unwrap();
        // The library policy needs a library: the world refuses it by name.
        let c = config(&args(
            Some("scenes/pushing.toml"),
            Some("push"),
            Some(Policy::Library),
        ))
        .unwrap();
        let err = viewer::World::new(c.scene, c.library, c.world).unwrap_err();
        assert!(err.to_string().contains("library"), "{err}");
        // A task the file does not have is named in the error.
        let err = config(&args(Some("scenes/pushing.toml"), Some("spin"), None)).unwrap_err();
        assert!(format!("{err:#}").contains("spin"), "{err:#}");
    }
}
