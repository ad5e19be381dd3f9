//! `serve` over Zenoh, on loopback only: two services ("two boards") with different poses and
//! subscribers in other processes (the Rust `vkterrain subscribe` and the Python example) get
//! the right frames with the right metadata; control over Zenoh moves the camera; a malformed
//! control message is counted, not fatal; status answers as a queryable.
#![cfg(feature = "zenoh")]

mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

fn exe(dir: &Path) -> Command {
    let mut c = common::cli::command();
    c.env("VKTERRAIN_RING_DIR", dir);
    c
}

fn ci_config() -> PathBuf {
    common::cli::shipped_config("ci.toml")
}

/// A free TCP port on 127.0.0.1 (bound and released: good enough on a test machine).
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn serve(dir: &Path, ring: &str, endpoint: &str, status: &Path) -> Child {
    exe(dir)
        .arg("serve")
        .arg("--config")
        .arg(ci_config())
        .args(["--width", "40", "--height", "30", "--ring", ring, "--zenoh"])
        .args(["--zenoh-listen", endpoint, "--status-file"])
        .arg(status)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn subscribe(dir: &Path, ring: &str, endpoint: &str, args: &[&str]) -> Output {
    exe(dir)
        .args(["subscribe", "--ring", ring, "--connect", endpoint])
        .args(args)
        .output()
        .unwrap()
}

fn status_json(path: &Path) -> Option<serde_json::Value> {
    serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()
}

fn wait_for(what: &str, mut ok: impl FnMut() -> bool) {
    let start = Instant::now();
    while !ok() {
        assert!(
            start.elapsed() < Duration::from_secs(90),
            "timed out: {what}"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// `key=value` pairs of every line of a subscriber's output.
/// A subscriber's `frame=...` line as key/value pairs.
type FrameFields = std::collections::BTreeMap<String, String>;

fn frames_of(out: &str) -> Vec<FrameFields> {
    out.lines()
        .filter(|l| l.starts_with("frame="))
        .map(|l| {
            l.split_whitespace()
                .filter_map(|kv| kv.split_once('='))
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect()
        })
        .collect()
}

/// A subscriber's output that succeeded and printed five frames: its stdout and the frames.
fn five_frames(o: &Output) -> (String, Vec<FrameFields>) {
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        o.status.success(),
        "{out}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let frames = frames_of(&out);
    assert_eq!(frames.len(), 5, "{out}");
    (out, frames)
}

fn python_with_zenoh() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import zenoh"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        assert!(
            std::env::var("CI").is_err(),
            "CI needs the eclipse-zenoh Python package (make test installs it)"
        );
        eprintln!("SKIPPING the Python subscriber: `pip install eclipse-zenoh==1.10.2`");
    }
    ok
}

#[test]
fn two_boards_two_subscribers_control_and_status_over_zenoh() {
    let tmp = tempfile::tempdir().unwrap();
    let (pa, pb) = (free_port(), free_port());
    let (ea, eb) = (format!("tcp/127.0.0.1:{pa}"), format!("tcp/127.0.0.1:{pb}"));
    let (sa, sb) = (tmp.path().join("a.json"), tmp.path().join("b.json"));
    let mut board_a = serve(tmp.path(), "board-a", &ea, &sa);
    let mut board_b = serve(tmp.path(), "board-b", &eb, &sb);
    wait_for("both boards running", || {
        [&sa, &sb]
            .iter()
            .all(|p| status_json(p).is_some_and(|s| s["frames_rendered"].as_u64() > Some(1)))
    });

    // Different poses, sent over Zenoh (the same validation as the control socket).
    let pose = |x: i32, fov: f64| {
        format!(
            r#"{{"pose":{{"position":[{x},300,700],"yaw_deg":15,"pitch_deg":-20}},"fov_deg":{fov}}}"#
        )
    };
    for (ring, ep, msg) in [
        ("board-a", &ea, pose(111, 41.0)),
        ("board-b", &eb, pose(222, 52.0)),
    ] {
        let o = subscribe(tmp.path(), ring, ep, &["--control", &msg]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    // A malformed message is counted as rejected; the board keeps rendering.
    let o = subscribe(
        tmp.path(),
        "board-a",
        &ea,
        &["--control", "{\"pose\": nonsense"],
    );
    assert!(o.status.success());
    wait_for("control applied and the bad message counted", || {
        status_json(&sa)
            .is_some_and(|s| s["camera"] == "control" && s["control_rejected"].as_u64() == Some(1))
            && status_json(&sb).is_some_and(|s| s["camera"] == "control")
    });

    // Subscriber 1 (Rust, another process) on board A.
    rust_subscriber_sees_its_board(tmp.path(), &ea);
    // Subscriber 2 (Python) on board B: board B's pose, never board A's.
    if python_with_zenoh() {
        python_subscriber_sees_its_board(tmp.path(), &eb);
    }

    // Status as a queryable: board B's own status.
    let o = subscribe(tmp.path(), "board-b", &eb, &["--status", "--seconds", "30"]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{out}");
    let s: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(s["ring"], "board-b");
    assert!(s["zenoh"]["published"].as_u64() > Some(0), "{s}");

    for child in [&mut board_a, &mut board_b] {
        // SAFETY: signalling our own children.
        unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    }
    for child in [board_a, board_b] {
        let o = child.wait_with_output().unwrap();
        assert_eq!(
            o.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
}

/// Five frames of board A (its ring `board-a` at `endpoint`) through the Rust subscriber in
/// another process: board A's size and pose (x 111, 41 degrees), rising frame numbers, a PNG.
fn rust_subscriber_sees_its_board(tmp: &Path, endpoint: &str) {
    let png = tmp.join("a.png");
    let o = subscribe(
        tmp,
        "board-a",
        endpoint,
        &[
            "--frames",
            "5",
            "--seconds",
            "60",
            "--save",
            png.to_str().unwrap(),
        ],
    );
    let (out, frames) = five_frames(&o);
    for f in &frames {
        assert_eq!(
            (f["width"].as_str(), f["height"].as_str()),
            ("40", "30"),
            "{out}"
        );
        assert_eq!(
            (f["x"].as_str(), f["vfov_deg"].as_str()),
            ("111", "41"),
            "{out}"
        );
    }
    let nums: Vec<u64> = frames.iter().map(|f| f["frame"].parse().unwrap()).collect();
    assert!(nums.windows(2).all(|w| w[1] > w[0]), "{out}");
    assert!(std::fs::read(&png).unwrap().starts_with(b"\x89PNG"));
}

/// Five frames of board B (ring `board-b` at `endpoint`) through the Python subscriber: board
/// B's pose (x 222), never board A's, and a PNG.
fn python_subscriber_sees_its_board(tmp: &Path, endpoint: &str) {
    let png_b = tmp.join("b.png");
    let o = Command::new("python3")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("consumers/python/zenoh_subscriber.py"))
        .args([
            "--ring",
            "board-b",
            "--connect",
            endpoint,
            "--frames",
            "5",
            "--seconds",
            "60",
        ])
        .arg("--save")
        .arg(&png_b)
        .output()
        .unwrap();
    let (out, frames) = five_frames(&o);
    for f in &frames {
        assert_eq!(f["x"].as_str(), "222.0", "{out}");
    }
    assert!(std::fs::read(&png_b).unwrap().starts_with(b"\x89PNG"));
}

fn rate(status: &Path, seconds: f64) -> f64 {
    let f = |s: &serde_json::Value| {
        (
            s["frames_rendered"].as_u64().unwrap(),
            s["uptime_s"].as_f64().unwrap(),
        )
    };
    let (f0, t0) = f(&status_json(status).unwrap());
    std::thread::sleep(Duration::from_secs_f64(seconds));
    let (f1, t1) = f(&status_json(status).unwrap());
    (f1 - f0) as f64 / (t1 - t0).max(1e-3)
}

#[test]
fn a_stalled_subscriber_never_slows_the_renderer() {
    if !python_with_zenoh() {
        return;
    }
    // 640x360 frames (0.9 MB) to a subscriber whose queue of one sample is full and never read:
    // its Zenoh session stops reading the socket, the link fills up, and the service drops
    // frames instead of waiting.
    let tmp = tempfile::tempdir().unwrap();
    let ep = format!("tcp/127.0.0.1:{}", free_port());
    let status = tmp.path().join("s.json");
    let mut board = exe(tmp.path())
        .arg("serve")
        .arg("--config")
        .arg(ci_config())
        .args([
            "--ring",
            "slow",
            "--zenoh",
            "--zenoh-listen",
            &ep,
            "--status-file",
        ])
        .arg(&status)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_for("running", || {
        status_json(&status).is_some_and(|s| s["frames_rendered"].as_u64() > Some(3))
    });
    let alone = rate(&status, 3.0);
    let mut stalled = Command::new("python3")
        .args([
            "-c",
            "import sys, time, zenoh, json\n\
             c = zenoh.Config(); c.insert_json5('connect/endpoints', json.dumps([sys.argv[1]]))\n\
             c.insert_json5('scouting/multicast/enabled', 'false')\n\
             s = zenoh.open(c)\n\
             sub = s.declare_subscriber('vkterrain/slow/frame', zenoh.handlers.FifoChannel(1))\n\
             time.sleep(60)",
            &ep,
        ])
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_secs(2));
    let with_stalled = rate(&status, 3.0);
    let s = status_json(&status).unwrap();
    eprintln!(
        "frames/s alone {alone:.1}, with a stalled subscriber {with_stalled:.1}: {}",
        s["zenoh"]
    );
    assert!(
        with_stalled >= 0.5 * alone,
        "a stalled subscriber slowed the renderer: {alone:.1} -> {with_stalled:.1} frames/s"
    );
    let _ = stalled.kill();
    let _ = stalled.wait();
    // SAFETY: signalling our own child.
    unsafe { libc::kill(board.id() as i32, libc::SIGTERM) };
    let start = Instant::now();
    while board.try_wait().unwrap().is_none() {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "serve did not stop"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let o = board.wait_with_output().unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}
