//! `cargo xtask view`: the interactive viewer on 127.0.0.1.

use anyhow::Context;
use dynamics::Scene;
use indicatif::{ProgressBar, ProgressStyle};
use library::{Library, LibrarySettings};
use std::net::{Ipv4Addr, SocketAddr};
use std::path::PathBuf;
use viewer::protocol::PolicyKind;
use viewer::{Viewer, ViewerConfig, WorldSettings};

/// Options of `cargo xtask view`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The library for the library policy. Default: results/finger.lib (written by `cargo xtask train`
    /// and `cargo xtask reproduce` with their default settings) if it exists, else that library built
    /// now (about 15 s) and saved there.
    #[arg(long)]
    library: Option<PathBuf>,
    /// Port on 127.0.0.1 (0: any free port).
    #[arg(long, default_value_t = 8080)]
    port: u16,
    /// The controller at start.
    #[arg(long, value_enum, default_value = "library")]
    policy: Policy,
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
            // Written by another version of this project: the default library is rebuilt below.
            Err(library::LibraryError::Version { found, expected }) => println!(
                "{} has format version {found}, this build reads {expected}: rebuilding it",
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
    let settings = LibrarySettings::default();
    println!("building the default library (as `cargo xtask train` does) ...");
    let bar = ProgressBar::new(settings.trajectories as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} trajectories  {elapsed_precise}")
            .expect("a valid template"),
    );
    let lib = Library::build(&Scene::flicking_finger(), &settings, |_, _| bar.inc(1))?;
    bar.finish_and_clear();
    std::fs::create_dir_all("results").context("creating results/")?;
    lib.save(&path)?;
    println!("saved {}", path.display());
    Ok(lib)
}

/// Run `cargo xtask view`.
pub fn run(args: &Args) -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "warn".into()),
        )
        .init();
    let library = library(args)?;
    let config = ViewerConfig {
        addr: SocketAddr::from((Ipv4Addr::LOCALHOST, args.port)),
        scene: Scene::flicking_finger(),
        library: Some(library),
        world: WorldSettings {
            policy: match args.policy {
                Policy::Library => PolicyKind::Library,
                Policy::Mpc => PolicyKind::Mpc,
                Policy::Off => PolicyKind::Off,
            },
            mpc_passes: args.mpc_passes,
            mpc_horizon: args.mpc_horizon,
            ..WorldSettings::default()
        },
    };
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
