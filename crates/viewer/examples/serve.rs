//! Serve the viewer on http://127.0.0.1:8080 with online MPC (no library needed) until Ctrl-C; open the
//! address in a browser, watch the finger learn to flick the ellipse, drag it with the mouse.
//!
//! ```sh
//! cargo run --release -p viewer --example serve [-- PORT]
//! ```
//!
//! `cargo xtask view` is the same with a library, its policy and more options.

use std::net::{Ipv4Addr, SocketAddr};
use viewer::protocol::PolicyKind;
use viewer::{Viewer, ViewerConfig, WorldSettings};

#[tokio::main]
async fn main() -> Result<(), Box<dyn std::error::Error>> {
    let port = match std::env::args().nth(1) {
        Some(p) => p.parse::<u16>()?,
        None => 8080,
    };
    let viewer = Viewer::bind(ViewerConfig {
        addr: SocketAddr::from((Ipv4Addr::LOCALHOST, port)),
        // The built-in scene file (scenes/finger.toml); the default world runs its spin task.
        scene: task::ProblemFile::builtin().scene,
        library: None,
        world: WorldSettings {
            policy: PolicyKind::Mpc,
            ..WorldSettings::default()
        },
    })
    .await?;
    println!("open http://{} (Ctrl-C stops)", viewer.local_addr()?);
    viewer
        .run(async {
            let _ = tokio::signal::ctrl_c().await;
        })
        .await?;
    Ok(())
}
