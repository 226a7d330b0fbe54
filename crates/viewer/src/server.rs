//! The web server: the page and its script from memory, and a WebSocket per client. The world runs on its
//! own thread at real time (times the speed), takes the clients' messages from a channel, and publishes
//! each frame on a watch channel, so that every client sees the latest frame and a slow one skips frames
//! instead of holding the simulation back.

use crate::error::ViewerError;
use crate::protocol::{ClientMessage, ServerMessage};
use crate::world::{World, WorldSettings};
use axum::Router;
use axum::extract::State;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use dynamics::Scene;
use futures_util::{SinkExt, StreamExt};
use library::Library;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use tokio::sync::{mpsc as async_mpsc, watch};

const INDEX: &str = include_str!("../assets/index.html");
const SCRIPT: &str = include_str!("../assets/viewer.js");
const STYLE: &str = include_str!("../assets/viewer.css");

/// What the viewer serves.
#[derive(Debug, Clone)]
pub struct ViewerConfig {
    /// Where to listen (the default is 127.0.0.1 on port 8080).
    pub addr: SocketAddr,
    /// The scene.
    pub scene: Scene,
    /// The library for the library policy, if any (it must fit the scene).
    pub library: Option<Library>,
    /// How the world starts.
    pub world: WorldSettings,
}

/// A message from a client, with the way back to it for an error reply.
type Input = (ClientMessage, async_mpsc::UnboundedSender<String>);

#[derive(Clone)]
struct AppState {
    inputs: mpsc::Sender<Input>,
    frames: watch::Receiver<Arc<str>>,
    hello: Arc<str>,
}

/// A bound, not yet running viewer: binding checks the address and the library, so that a port in use
/// or a library for another scene is an error at start.
#[derive(Debug)]
pub struct Viewer {
    listener: tokio::net::TcpListener,
    world: World,
}

fn json(message: &ServerMessage) -> String {
    serde_json::to_string(message).expect("server messages serialise")
}

/// The world's current frame as a message.
fn frame_json(world: &World) -> String {
    json(&ServerMessage::Frame(Box::new(world.frame())))
}

impl Viewer {
    /// Check the library against the scene and bind the address.
    pub async fn bind(config: ViewerConfig) -> Result<Self, ViewerError> {
        let world = World::new(config.scene, config.library, config.world)?;
        let listener = tokio::net::TcpListener::bind(config.addr)
            .await
            .map_err(|source| ViewerError::Bind {
                addr: config.addr,
                source,
            })?;
        Ok(Viewer { listener, world })
    }

    /// The address it listens on (the actual port when 0 was asked for).
    pub fn local_addr(&self) -> Result<SocketAddr, ViewerError> {
        self.listener.local_addr().map_err(ViewerError::Serve)
    }

    /// Serve until `shutdown` completes, then stop the world and close every connection.
    pub async fn run(
        self,
        shutdown: impl std::future::Future<Output = ()> + Send + 'static,
    ) -> Result<(), ViewerError> {
        let (inputs, input_rx) = mpsc::channel::<Input>();
        let first = frame_json(&self.world);
        let (frame_tx, frames) = watch::channel::<Arc<str>>(first.into());
        let hello: Arc<str> = json(&self.world.hello()).into();
        let stop = Arc::new(AtomicBool::new(false));
        let world = self.world;
        let stop_world = stop.clone();
        let simulation = std::thread::Builder::new()
            .name("viewer-world".into())
            .spawn(move || simulate(world, input_rx, frame_tx, &stop_world))
            .map_err(ViewerError::Serve)?;
        let app = Router::new()
            .route("/", get(index))
            .route("/viewer.js", get(script))
            .route("/viewer.css", get(style))
            .route("/ws", get(upgrade))
            .with_state(AppState {
                inputs,
                frames,
                hello,
            });
        let stop_server = stop.clone();
        let served = axum::serve(self.listener, app)
            .with_graceful_shutdown(async move {
                shutdown.await;
                // Stopping the world drops the frame channel, which ends every client's connection.
                stop_server.store(true, Ordering::Relaxed);
            })
            .await;
        stop.store(true, Ordering::Relaxed);
        let _ = simulation.join();
        served.map_err(ViewerError::Serve)
    }
}

/// The world's thread: apply inputs as they come, step at real time, publish frames.
fn simulate(
    mut world: World,
    inputs: mpsc::Receiver<Input>,
    frames: watch::Sender<Arc<str>>,
    stop: &AtomicBool,
) {
    let mut next = Instant::now();
    let apply = |world: &mut World, (message, reply): Input| {
        tracing::debug!(?message, "input");
        if let Err(e) = world.apply(message) {
            tracing::warn!(error = %e, "refused a message");
            let _ = reply.send(json(&ServerMessage::Error {
                message: e.to_string(),
            }));
        }
    };
    while !stop.load(Ordering::Relaxed) {
        // Wait for a message or the next step, then take every message waiting: a flood of input
        // cannot starve the steps, which are checked on every round.
        let wait = next.saturating_duration_since(Instant::now());
        let mut applied = false;
        match inputs.recv_timeout(wait.min(Duration::from_millis(50))) {
            Ok(input) => {
                apply(&mut world, input);
                applied = true;
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            // Every sender is gone: the server has stopped.
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
        }
        while let Ok(input) = inputs.try_recv() {
            apply(&mut world, input);
            applied = true;
        }
        if applied && world.paused() {
            // Time stands still, but the page should see what the input did.
            let _ = frames.send(frame_json(&world).into());
        }
        let now = Instant::now();
        if now < next {
            continue;
        }
        if world.paused() {
            next = now + Duration::from_millis(100);
        } else {
            if let Err(e) = world.advance() {
                tracing::warn!(error = %e, "the step failed; the world was reset");
                let _ = world.apply(ClientMessage::Reset);
            }
            next += Duration::from_secs_f64(world.h() / world.speed());
            // Fallen behind by more than a moment (a slow controller, a busy machine): run on from now
            // rather than racing to catch up.
            if next + Duration::from_millis(250) < now {
                next = now;
            }
        }
        let _ = frames.send(frame_json(&world).into());
    }
}

async fn index() -> Response {
    ([(header::CONTENT_TYPE, "text/html; charset=utf-8")], INDEX).into_response()
}

async fn script() -> Response {
    (
        [(header::CONTENT_TYPE, "text/javascript; charset=utf-8")],
        SCRIPT,
    )
        .into_response()
}

async fn style() -> Response {
    ([(header::CONTENT_TYPE, "text/css; charset=utf-8")], STYLE).into_response()
}

async fn upgrade(ws: WebSocketUpgrade, State(state): State<AppState>) -> Response {
    ws.on_upgrade(move |socket| client(socket, state))
}

/// One client: the hello, then every new frame out and every message in, until either side closes.
async fn client(socket: WebSocket, state: AppState) {
    let (mut sink, mut stream) = socket.split();
    let (reply_tx, mut replies) = async_mpsc::unbounded_channel::<String>();
    let mut frames = state.frames.clone();
    if sink
        .send(Message::Text(state.hello.to_string().into()))
        .await
        .is_err()
    {
        return;
    }
    frames.mark_changed();
    loop {
        tokio::select! {
            changed = frames.changed() => {
                if changed.is_err() {
                    break;
                }
                let frame = frames.borrow_and_update().clone();
                if sink.send(Message::Text(frame.to_string().into())).await.is_err() {
                    break;
                }
            }
            Some(reply) = replies.recv() => {
                if sink.send(Message::Text(reply.into())).await.is_err() {
                    break;
                }
            }
            message = stream.next() => match message {
                None | Some(Err(_)) | Some(Ok(Message::Close(_))) => break,
                Some(Ok(Message::Text(text))) => match ClientMessage::parse(text.as_str()) {
                    Ok(message) => {
                        if state.inputs.send((message, reply_tx.clone())).is_err() {
                            break;
                        }
                    }
                    Err(e) => {
                        tracing::warn!(error = %e, "malformed message");
                        let reply = json(&ServerMessage::Error { message: e.to_string() });
                        if sink.send(Message::Text(reply.into())).await.is_err() {
                            break;
                        }
                    }
                },
                Some(Ok(Message::Binary(_))) => {
                    tracing::warn!("binary message");
                    let reply = json(&ServerMessage::Error {
                        message: "malformed message: binary messages are not part of the protocol".into(),
                    });
                    if sink.send(Message::Text(reply.into())).await.is_err() {
                        break;
                    }
                }
                Some(Ok(_)) => {}
            }
        }
    }
}
