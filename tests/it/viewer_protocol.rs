//! The viewer's WebSocket protocol end to end over a real socket: frames stream, a drag moves the world,
//! malformed messages get error replies and never end the connection, two clients share one world, and
//! a port in use or a library for another scene fails at start.

use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use std::net::{Ipv4Addr, SocketAddr};
use std::time::Duration;
use tokio::net::TcpStream;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};
use viewer::protocol::PolicyKind;
use viewer::{Viewer, ViewerConfig, ViewerError, WorldSettings};

type Socket = WebSocketStream<MaybeTlsStream<TcpStream>>;

fn config(port: u16) -> ViewerConfig {
    ViewerConfig {
        addr: SocketAddr::from((Ipv4Addr::LOCALHOST, port)),
        scene: task::ProblemFile::builtin().scene,
        library: None,
        world: WorldSettings {
            policy: PolicyKind::Off,
            speed: 4.0,
            ..WorldSettings::default()
        },
    }
}

/// The next text message as JSON (pings and the like skipped), within a few seconds.
async fn next(socket: &mut Socket) -> Value {
    loop {
        let message = tokio::time::timeout(Duration::from_secs(10), socket.next())
            .await
            .expect("a message within 10 s")
            .expect("the connection stays open")
            .expect("a well-formed frame");
        if let Message::Text(text) = message {
            return serde_json::from_str(text.as_str()).expect("JSON");
        }
    }
}

/// The next message of the given type, skipping others.
async fn next_of(socket: &mut Socket, kind: &str) -> Value {
    loop {
        let m = next(socket).await;
        if m["type"] == kind {
            return m;
        }
    }
}

/// The first frame at or after simulated time `t`.
async fn frame_after(socket: &mut Socket, t: f64) -> Value {
    loop {
        let m = next_of(socket, "frame").await;
        if m["t"].as_f64().unwrap() >= t {
            return m;
        }
    }
}

async fn send(socket: &mut Socket, message: Value) {
    socket
        .send(Message::Text(message.to_string().into()))
        .await
        .unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn frames_stream_a_drag_spins_the_ellipse_and_bad_messages_are_answered_not_fatal() {
    let viewer = Viewer::bind(config(0)).await.unwrap();
    let addr = viewer.local_addr().unwrap();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(viewer.run(async {
        let _ = stopped.await;
    }));
    let url = format!("ws://{addr}/ws");
    let (mut a, _) = tokio_tungstenite::connect_async(&url).await.unwrap();
    let hello = next(&mut a).await;
    assert_eq!(hello["type"], "hello");
    assert_eq!(hello["bodies"].as_array().unwrap().len(), 3);
    assert_eq!(hello["library"], false);

    // Frames arrive with time moving on.
    let f1 = next_of(&mut a, "frame").await;
    let f2 = frame_after(&mut a, f1["t"].as_f64().unwrap() + 0.2).await;
    assert!(f2["step"].as_u64().unwrap() > f1["step"].as_u64().unwrap());
    // With no torques and no contact the free ellipse rests.
    assert!(f2["x"][5].as_f64().unwrap().abs() < 1e-9, "{f2}");

    // Grab the free ellipse (body 2, centre (0, -3), angle 0) at the end of its long axis and pull that
    // point up: the ellipse turns counter-clockwise.
    let t0 = f2["t"].as_f64().unwrap();
    send(
        &mut a,
        json!({"type": "grab", "body": 2, "point": [0.7, -3.0]}),
    )
    .await;
    send(&mut a, json!({"type": "drag", "target": [0.7, -1.5]})).await;
    let pulled = frame_after(&mut a, t0 + 1.0).await;
    assert!(pulled["spring"]["body"] == 2, "{pulled}");
    let turned = pulled["x"][2].as_f64().unwrap() - f2["x"][2].as_f64().unwrap();
    assert!(turned > 0.3, "the drag should turn the ellipse: {pulled}");
    assert!(pulled["perturbations"].as_u64().unwrap() >= 1);
    send(&mut a, json!({"type": "release"})).await;
    let released = frame_after(&mut a, pulled["t"].as_f64().unwrap() + 0.2).await;
    assert!(released["spring"].is_null());

    // Malformed and out-of-range messages: each gets an error reply, the stream goes on.
    for bad in [
        Message::Text("not json".into()),
        Message::Text(r#"{"type":"fly"}"#.into()),
        Message::Text(r#"{"type":"sigma","sigma":-1}"#.into()),
        Message::Text(r#"{"type":"sigma","sigma":"big"}"#.into()),
        Message::Text(r#"{"type":"grab","body":9,"point":[0,0]}"#.into()),
        Message::Text(r#"{"type":"speed","speed":1e9}"#.into()),
        Message::Text(r#"{"type":"policy","policy":"library"}"#.into()),
        Message::Binary(vec![1, 2, 3].into()),
    ] {
        let shown = format!("{bad:?}");
        a.send(bad).await.unwrap();
        let reply = next_of(&mut a, "error").await;
        assert!(
            !reply["message"].as_str().unwrap().is_empty(),
            "{shown}: {reply}"
        );
    }
    let alive = next_of(&mut a, "frame").await;
    assert!(alive["t"].as_f64().unwrap() > released["t"].as_f64().unwrap());

    // A second client at the same time: its own hello and frames of the same world; its reset is seen by
    // the first.
    let (mut b, _) = tokio_tungstenite::connect_async(&url).await.unwrap();
    assert_eq!(next(&mut b).await["type"], "hello");
    let fb = next_of(&mut b, "frame").await;
    assert!(fb["t"].as_f64().unwrap() > 0.5);
    send(&mut b, json!({"type": "reset"})).await;
    loop {
        let f = next_of(&mut a, "frame").await;
        if f["t"].as_f64().unwrap() < 0.5 {
            assert_eq!(f["perturbations"], 0);
            break;
        }
    }
    // Pause stops time for both.
    send(&mut b, json!({"type": "pause", "paused": true})).await;
    let paused = loop {
        let f = next_of(&mut a, "frame").await;
        if f["paused"] == true {
            break f;
        }
    };
    tokio::time::sleep(Duration::from_millis(300)).await;
    send(&mut a, json!({"type": "kick", "std": 1.0})).await;
    let later = loop {
        let f = next_of(&mut a, "frame").await;
        if f["perturbations"] == 1 {
            break f;
        }
    };
    assert_eq!(later["t"], paused["t"], "time stands still");
    assert_ne!(
        later["x"][3], paused["x"][3],
        "the kick applies while paused"
    );

    drop(a);
    drop(b);
    stop.send(()).unwrap();
    tokio::time::timeout(Duration::from_secs(10), server)
        .await
        .expect("the server stops")
        .unwrap()
        .unwrap();
}

#[tokio::test]
async fn a_port_in_use_and_a_library_for_another_scene_are_errors_at_start() {
    let taken = std::net::TcpListener::bind((Ipv4Addr::LOCALHOST, 0)).unwrap();
    let port = taken.local_addr().unwrap().port();
    let err = Viewer::bind(config(port)).await.unwrap_err();
    assert!(matches!(err, ViewerError::Bind { .. }), "{err}");
    assert!(err.to_string().contains(&port.to_string()), "{err}");

    // A small library of the finger, offered for a finger with other gravity.
    let settings = library::LibrarySettings {
        trajectories: 2,
        horizon: 10,
        first_passes: 5,
        warm_passes: 2,
        ..library::LibrarySettings::paper()
    };
    let lib =
        library::Library::build(&task::ProblemFile::builtin(), None, &settings, |_, _| {}).unwrap();
    let mut spec = task::ProblemFile::builtin().scene.spec().clone();
    spec.gravity = [0.0, -9.81];
    let mut other = config(0);
    other.scene = dynamics::Scene::new(spec).unwrap();
    other.library = Some(lib);
    let err = Viewer::bind(other).await.unwrap_err();
    assert!(
        matches!(
            err,
            ViewerError::Library(library::LibraryError::SceneMismatch(_))
        ),
        "{err}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flood_of_refused_messages_and_a_silent_connection_change_nothing_for_other_clients() {
    let viewer = Viewer::bind(config(0))
        .await
        .unwrap()
        .with_idle_timeout(Duration::from_secs(1));
    let addr = viewer.local_addr().unwrap();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(viewer.run(async {
        let _ = stopped.await;
    }));
    let url = format!("ws://{addr}/ws");
    // A half-open connection: TCP only, never a request. The server closes it after the idle timeout.
    let mut silent = TcpStream::connect(addr).await.unwrap();
    // Flooders: refused messages (a kick out of range), never reading the replies, for 2 s.
    let mut flooders = Vec::new();
    for _ in 0..4 {
        let (mut f, _) = tokio_tungstenite::connect_async(&url).await.unwrap();
        flooders.push(tokio::spawn(async move {
            let bad = json!({"type": "kick", "std": 1e9}).to_string();
            let until = tokio::time::Instant::now() + Duration::from_secs(2);
            let mut sent = 0u64;
            // A send blocks once the server stops reading this client (it is busy writing replies the
            // flooder never reads): that is the flood's backpressure, and the flood ends at its deadline.
            while let Ok(Ok(())) =
                tokio::time::timeout_at(until, f.send(Message::Text(bad.clone().into()))).await
            {
                sent += 1;
            }
            (f, sent)
        }));
    }
    // A well-behaved client meanwhile, reading all along: it gets the answer to its own bad message,
    // sees simulated time advance, and stays connected past several idle timeouts without sending.
    let (mut watcher, _) = tokio_tungstenite::connect_async(&url).await.unwrap();
    let watching = tokio::spawn(async move {
        let first = next_of(&mut watcher, "frame").await["t"].as_f64().unwrap();
        send(&mut watcher, json!({"type": "sigma", "sigma": -1.0})).await;
        let error = next_of(&mut watcher, "error").await;
        assert!(
            error["message"].as_str().unwrap().contains("sigma"),
            "{error}"
        );
        let until = tokio::time::Instant::now() + Duration::from_secs(5);
        let mut last = first;
        while tokio::time::Instant::now() < until {
            last = next_of(&mut watcher, "frame").await["t"].as_f64().unwrap();
        }
        (first, last)
    });
    let mut total = 0;
    for f in flooders {
        // (A flooder that neither sends nor reads for the idle timeout is closed like any silent
        // connection; it does not answer pings.)
        let (_, sent) = f.await.unwrap();
        total += sent;
    }
    println!("the flood sent {total} messages");
    assert!(total > 200, "the flood sent only {total} messages");
    // The silent connection was closed by the server (EOF or reset), not held.
    let mut buf = [0u8; 16];
    let read = tokio::time::timeout(
        Duration::from_secs(10),
        tokio::io::AsyncReadExt::read(&mut silent, &mut buf),
    )
    .await
    .expect("the server closes a silent connection within its idle timeout");
    assert!(matches!(read, Ok(0) | Err(_)), "{read:?}");
    let (first, last) = watching.await.unwrap();
    // At speed 4, 5 s of reading is 20 simulated seconds; the flood must not have held the clock back.
    assert!(
        last - first > 10.0,
        "simulated time went from {first} to {last}"
    );
    stop.send(()).unwrap();
    tokio::time::timeout(Duration::from_secs(10), server)
        .await
        .expect("the server stops")
        .unwrap()
        .unwrap();
}

/// Issue 27: a `reset` carrying a field it does not have was accepted, and a message over the size limit
/// dropped the connection without a close frame. The first is now answered with an error, the second
/// closes with code 1009 (message too big) and a reason.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn extra_fields_are_refused_and_an_oversized_message_closes_with_its_reason() {
    let viewer = Viewer::bind(config(0)).await.unwrap();
    let addr = viewer.local_addr().unwrap();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(viewer.run(async {
        let _ = stopped.await;
    }));
    let url = format!("ws://{addr}/ws");
    let (mut a, _) = tokio_tungstenite::connect_async(&url).await.unwrap();
    assert_eq!(next(&mut a).await["type"], "hello");
    send(&mut a, json!({"type": "reset", "hard": true})).await;
    let e = next_of(&mut a, "error").await;
    assert!(
        e["message"]
            .as_str()
            .unwrap()
            .contains("unknown field `hard`"),
        "{e}"
    );
    let big = format!(
        "{{\"type\":\"kick\",\"std\":1.0,\"pad\":\"{}\"}}",
        "x".repeat(viewer::MAX_CLIENT_MESSAGE + 10)
    );
    a.send(Message::Text(big.into())).await.unwrap();
    let close = loop {
        match tokio::time::timeout(Duration::from_secs(10), a.next())
            .await
            .expect("an answer within 10 s")
        {
            Some(Ok(Message::Close(frame))) => break frame,
            Some(Ok(_)) => continue,
            other => panic!("the connection ended without a close frame: {other:?}"),
        }
    };
    let frame = close.expect("a close frame with a code");
    assert_eq!(u16::from(frame.code), 1009, "{frame:?}");
    assert!(frame.reason.contains("limit"), "{frame:?}");
    stop.send(()).unwrap();
    tokio::time::timeout(Duration::from_secs(10), server)
        .await
        .expect("the server stops")
        .unwrap()
        .unwrap();
}
