//! The web server: the page and its script from memory, and a WebSocket per client. The world runs on its
//! own thread at real time (times the speed), takes the clients' messages from a channel, and publishes
//! each frame on a watch channel, so that every client sees the latest frame and a slow one skips frames
//! instead of holding the simulation back.
//!
//! Under load nothing grows without bound and nothing stalls the world's clock: the input channel holds
//! [`INPUT_CAPACITY`] messages and each client's share of it [`CLIENT_INPUT_CAPACITY`] (a message past
//! either is dropped and its client told so, so a flooding client cannot crowd out the others), each
//! client's replies [`REPLY_CAPACITY`], warnings about refused or malformed messages are
//! logged at most once a second with a count, and a connection that sends nothing for the idle timeout
//! ([`DEFAULT_IDLE_TIMEOUT`]; WebSocket clients answer the server's pings, so only dead, silent and
//! half-open connections are idle) is closed.

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
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use tokio::sync::{mpsc as async_mpsc, watch};

/// Messages waiting for the world at most, from all clients; more are refused with a reply, not queued.
pub const INPUT_CAPACITY: usize = 1024;
/// Messages waiting for the world at most from one client: a flooding client's excess is refused, and
/// the others' messages still get through.
pub const CLIENT_INPUT_CAPACITY: usize = 32;
/// Replies waiting for one client at most; more are dropped.
pub const REPLY_CAPACITY: usize = 64;
/// A connection that sends nothing for this long is closed (see [`Viewer::with_idle_timeout`]).
pub const DEFAULT_IDLE_TIMEOUT: Duration = Duration::from_secs(30);

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

/// A message from a client, with the way back to it for an error reply, and the client's count of
/// messages waiting.
type Input = (ClientMessage, async_mpsc::Sender<String>, Arc<AtomicUsize>);

#[derive(Clone)]
struct AppState {
    inputs: mpsc::SyncSender<Input>,
    frames: watch::Receiver<Arc<str>>,
    hello: Arc<str>,
    idle_timeout: Duration,
}

/// A warning logged at most once a second, with the number of times it happened since the last.
#[derive(Debug)]
struct Throttled {
    what: &'static str,
    since: usize,
    last: Option<Instant>,
}

impl Throttled {
    const fn new(what: &'static str) -> Self {
        Throttled {
            what,
            since: 0,
            last: None,
        }
    }

    fn warn(&mut self, error: &dyn std::fmt::Display) {
        self.since += 1;
        let now = Instant::now();
        if self
            .last
            .is_none_or(|t| now.duration_since(t) >= Duration::from_secs(1))
        {
            tracing::warn!(count = self.since, error = %error, "{}", self.what);
            self.since = 0;
            self.last = Some(now);
        }
    }
}

/// A bound, not yet running viewer: binding checks the address and the library, so that a port in use
/// or a library for another scene is an error at start.
#[derive(Debug)]
pub struct Viewer {
    listener: tokio::net::TcpListener,
    world: World,
    idle_timeout: Duration,
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
        Ok(Viewer {
            listener,
            world,
            idle_timeout: DEFAULT_IDLE_TIMEOUT,
        })
    }

    /// Close connections that send nothing for `timeout` (default [`DEFAULT_IDLE_TIMEOUT`], at least
    /// 30 ms). WebSocket clients are pinged three times per timeout, and a client that reads its frames
    /// answers, so only dead, silent and half-open connections time out.
    pub fn with_idle_timeout(mut self, timeout: Duration) -> Self {
        self.idle_timeout = timeout.max(Duration::from_millis(30));
        self
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
        let (inputs, input_rx) = mpsc::sync_channel::<Input>(INPUT_CAPACITY);
        let first = frame_json(&self.world);
        let (frame_tx, frames) = watch::channel::<Arc<str>>(first.into());
        let hello: Arc<str> = json(&self.world.hello()).into();
        let stop = Arc::new(AtomicBool::new(false));
        let world = self.world;
        let stop_world = stop.clone();
        // A panic in the world's thread (a bug) is told to every client as an error message and stops
        // the server with an error, rather than leaving it serving a world that no longer moves.
        let (died_tx, died_rx) = tokio::sync::oneshot::channel::<String>();
        let simulation = std::thread::Builder::new()
            .name("viewer-world".into())
            .spawn(move || {
                let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    simulate(world, input_rx, &frame_tx, &stop_world)
                }));
                if let Err(payload) = outcome {
                    let what = payload
                        .downcast_ref::<&str>()
                        .map(|s| s.to_string())
                        .or_else(|| payload.downcast_ref::<String>().cloned())
                        .unwrap_or_else(|| "a panic without a message".into());
                    let message = ViewerError::WorldDied(what.clone()).to_string();
                    let _ = frame_tx.send(json(&ServerMessage::Error { message }).into());
                    let _ = died_tx.send(what);
                }
            })
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
                idle_timeout: self.idle_timeout,
            });
        let stop_server = stop.clone();
        let listener = IdleListener {
            inner: self.listener,
            timeout: self.idle_timeout,
        };
        let died = Arc::new(std::sync::Mutex::new(None::<String>));
        let died_seen = died.clone();
        let served = axum::serve(listener, app)
            .with_graceful_shutdown(async move {
                tokio::select! {
                    () = shutdown => {}
                    Ok(what) = died_rx => {
                        *died_seen.lock().unwrap_or_else(|p| p.into_inner()) = Some(what);
                    }
                }
                // Stopping the world drops the frame channel, which ends every client's connection.
                stop_server.store(true, Ordering::Relaxed);
            })
            .await;
        stop.store(true, Ordering::Relaxed);
        let _ = simulation.join();
        if let Some(what) = died.lock().unwrap_or_else(|p| p.into_inner()).take() {
            return Err(ViewerError::WorldDied(what));
        }
        served.map_err(ViewerError::Serve)
    }
}

/// The world's thread: apply inputs as they come, step at real time, publish frames.
fn simulate(
    mut world: World,
    inputs: mpsc::Receiver<Input>,
    frames: &watch::Sender<Arc<str>>,
    stop: &AtomicBool,
) {
    let mut next = Instant::now();
    let mut refused = Throttled::new("refused messages");
    let mut apply = |world: &mut World, (message, reply, waiting): Input| {
        tracing::debug!(?message, "input");
        waiting.fetch_sub(1, Ordering::Relaxed);
        if let Err(e) = world.apply(message) {
            refused.warn(&e);
            // A client that does not read its replies loses them, not the server its memory.
            let _ = reply.try_send(json(&ServerMessage::Error {
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

/// The largest message a client may send (its messages are a few hundred bytes); a longer one closes the
/// connection with code 1009 (message too big) and the reason.
pub const MAX_CLIENT_MESSAGE: usize = 64 << 10;

/// The largest message the server reads whole before closing. A message over [`MAX_CLIENT_MESSAGE`] and up to
/// this size is read and the connection closed with the full closing handshake, so the close frame always
/// arrives; a longer one is refused from its frame header and the connection dropped once the close frame is
/// sent (a peer still sending then may see a reset instead of the frame).
pub const MAX_READ_MESSAGE: usize = 1 << 20;

/// How long a closing connection waits for the client's answering close frame.
const CLOSING_WAIT: Duration = Duration::from_secs(2);

async fn upgrade(ws: WebSocketUpgrade, State(state): State<AppState>) -> Response {
    ws.max_message_size(MAX_READ_MESSAGE)
        .max_frame_size(MAX_READ_MESSAGE)
        .on_upgrade(move |socket| client(socket, state))
}

/// The close frame for a message over [`MAX_CLIENT_MESSAGE`].
fn too_big() -> Message {
    Message::Close(Some(axum::extract::ws::CloseFrame {
        code: 1009,
        reason: format!("message over the {MAX_CLIENT_MESSAGE}-byte limit").into(),
    }))
}

/// The closing handshake's second half: discard what the client still sends until its close frame, the end
/// of the stream, an error or [`CLOSING_WAIT`]. Dropping a socket with unread input makes the kernel reset
/// the connection, which can discard the close frame just sent before the client reads it.
async fn drain(stream: &mut futures_util::stream::SplitStream<WebSocket>) {
    let _ = tokio::time::timeout(CLOSING_WAIT, async {
        while let Some(Ok(message)) = stream.next().await {
            if matches!(message, Message::Close(_)) {
                break;
            }
        }
    })
    .await;
}

/// One client: the hello, then every new frame out and every message in, until either side closes.
async fn client(socket: WebSocket, state: AppState) {
    let (mut sink, mut stream) = socket.split();
    let (reply_tx, mut replies) = async_mpsc::channel::<String>(REPLY_CAPACITY);
    let mut frames = state.frames.clone();
    let mut malformed = Throttled::new("malformed messages");
    let waiting = Arc::new(AtomicUsize::new(0));
    // Pings three times per idle timeout: the client's pongs keep a live connection from being idle.
    let mut ping = tokio::time::interval(state.idle_timeout / 3);
    ping.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
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
            _ = ping.tick() => {
                if sink.send(Message::Ping(Vec::new().into())).await.is_err() {
                    break;
                }
            }
            message = stream.next() => match message {
                None | Some(Ok(Message::Close(_))) => break,
                Some(Err(e)) => {
                    // Say why before closing: a message over the limit (1009), or a broken frame (1002).
                    let reason = e.to_string();
                    let code = if reason.contains("too long") || reason.contains("limit") {
                        1009
                    } else {
                        1002
                    };
                    let close = if code == 1009 {
                        too_big()
                    } else {
                        Message::Close(Some(axum::extract::ws::CloseFrame {
                            code,
                            reason: reason.chars().take(100).collect::<String>().into(),
                        }))
                    };
                    let _ = sink.send(close).await;
                    break;
                }
                Some(Ok(Message::Text(text) )) if text.len() > MAX_CLIENT_MESSAGE => {
                    if sink.send(too_big()).await.is_ok() {
                        drain(&mut stream).await;
                    }
                    break;
                }
                Some(Ok(Message::Binary(data))) if data.len() > MAX_CLIENT_MESSAGE => {
                    if sink.send(too_big()).await.is_ok() {
                        drain(&mut stream).await;
                    }
                    break;
                }
                Some(Ok(Message::Text(text))) => match ClientMessage::parse(text.as_str()) {
                    Ok(message) => match enqueue(&state.inputs, message, &reply_tx, &waiting) {
                        Ok(()) => {}
                        Err(mpsc::TrySendError::Full(())) => {
                            let e = "the world is busy: message dropped (too many waiting); send fewer";
                            malformed.warn(&e);
                            let reply = json(&ServerMessage::Error { message: e.into() });
                            if sink.send(Message::Text(reply.into())).await.is_err() {
                                break;
                            }
                        }
                        Err(mpsc::TrySendError::Disconnected(_)) => break,
                    },
                    Err(e) => {
                        malformed.warn(&e);
                        let reply = json(&ServerMessage::Error { message: e.to_string() });
                        if sink.send(Message::Text(reply.into())).await.is_err() {
                            break;
                        }
                    }
                },
                Some(Ok(Message::Binary(_))) => {
                    malformed.warn(&"binary message");
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

/// Queue a client's message for the world unless the client or everyone has too many waiting.
fn enqueue(
    inputs: &mpsc::SyncSender<Input>,
    message: ClientMessage,
    reply: &async_mpsc::Sender<String>,
    waiting: &Arc<AtomicUsize>,
) -> Result<(), mpsc::TrySendError<()>> {
    if waiting.fetch_add(1, Ordering::Relaxed) >= CLIENT_INPUT_CAPACITY {
        waiting.fetch_sub(1, Ordering::Relaxed);
        return Err(mpsc::TrySendError::Full(()));
    }
    inputs
        .try_send((message, reply.clone(), waiting.clone()))
        .map_err(|e| {
            waiting.fetch_sub(1, Ordering::Relaxed);
            match e {
                mpsc::TrySendError::Full(_) => mpsc::TrySendError::Full(()),
                mpsc::TrySendError::Disconnected(_) => mpsc::TrySendError::Disconnected(()),
            }
        })
}

/// The TCP listener with an idle timeout on every connection ([`IdleStream`]).
struct IdleListener {
    inner: tokio::net::TcpListener,
    timeout: Duration,
}

impl axum::serve::Listener for IdleListener {
    type Io = IdleStream;
    type Addr = SocketAddr;

    async fn accept(&mut self) -> (Self::Io, Self::Addr) {
        let (stream, addr) = axum::serve::Listener::accept(&mut self.inner).await;
        let _ = stream.set_nodelay(true);
        (
            IdleStream {
                inner: stream,
                timeout: self.timeout,
                deadline: Box::pin(tokio::time::sleep(self.timeout)),
            },
            addr,
        )
    }

    fn local_addr(&self) -> std::io::Result<Self::Addr> {
        self.inner.local_addr()
    }
}

/// A connection whose reads fail with `TimedOut` once it has sent nothing for the timeout: a half-open or
/// silent connection (a request never finished, a peer gone without a word) is closed instead of held.
struct IdleStream {
    inner: tokio::net::TcpStream,
    timeout: Duration,
    deadline: std::pin::Pin<Box<tokio::time::Sleep>>,
}

impl tokio::io::AsyncRead for IdleStream {
    fn poll_read(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &mut tokio::io::ReadBuf<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        use std::task::Poll;
        let before = buf.filled().len();
        match std::pin::Pin::new(&mut self.inner).poll_read(cx, buf) {
            Poll::Ready(result) => {
                if buf.filled().len() > before {
                    let at = tokio::time::Instant::now() + self.timeout;
                    self.deadline.as_mut().reset(at);
                }
                Poll::Ready(result)
            }
            Poll::Pending => match self.deadline.as_mut().poll(cx) {
                Poll::Ready(()) => Poll::Ready(Err(std::io::Error::new(
                    std::io::ErrorKind::TimedOut,
                    "the connection sent nothing for the idle timeout",
                ))),
                Poll::Pending => Poll::Pending,
            },
        }
    }
}

impl tokio::io::AsyncWrite for IdleStream {
    fn poll_write(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &[u8],
    ) -> std::task::Poll<std::io::Result<usize>> {
        std::pin::Pin::new(&mut self.inner).poll_write(cx, buf)
    }

    fn poll_flush(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}
