//! `vkterrain serve` end to end (validation layers on): frames reach a ring consumer, a fuzzed
//! control channel is rejected message by message while rendering goes on, a resolution change
//! starts a new ring generation, `vkterrain status` reports, and SIGTERM shuts down cleanly.

mod common;

use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use vkterrain::output::ring::layout::STATE_CLOSED;
use vkterrain::output::ring::{Next, RingLocation, RingReader};

/// Rings of these tests live in the temporary directory `dir` of each test (mode 0700).
fn exe_in(dir: &Path) -> Command {
    let mut c = common::cli::command();
    c.env("VKTERRAIN_RING_DIR", dir)
        .env("VKTERRAIN_RING_OWNER", euid().to_string());
    c
}

fn exe() -> Command {
    exe_in(Path::new("/nonexistent-ring-dir"))
}

fn euid() -> u32 {
    // SAFETY: no arguments.
    unsafe { libc::geteuid() }
}

fn open_ring(dir: &Path, name: &str, timeout: Duration) -> RingReader {
    RingReader::open_wait(
        &RingLocation::new(dir, name).unwrap(),
        Some(euid()),
        timeout,
    )
    .unwrap()
}

fn ci_config() -> PathBuf {
    common::cli::shipped_config("ci.toml")
}

fn wait_exit(mut child: Child, limit: Duration) -> Output {
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > limit {
            let _ = child.kill();
            panic!("serve did not exit within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    child.wait_with_output().unwrap()
}

fn next_frame(r: &mut RingReader) -> vkterrain::output::ring::FrameMeta {
    let start = Instant::now();
    loop {
        assert!(start.elapsed() < Duration::from_secs(60), "no frame");
        match r.wait_next(Duration::from_secs(5)).unwrap() {
            Next::Frame(m) => return m,
            Next::Closed => panic!("ring closed unexpectedly"),
            _ => {}
        }
    }
}

fn status_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn serve_fuzzed_control_resize_status_and_sigterm() {
    let tmp = tempfile::tempdir().unwrap();
    let name = format!("vkt-serve-{}", std::process::id());
    let sock_path = tmp.path().join("control.sock");
    let status_path = tmp.path().join("status.json");
    let child = exe_in(tmp.path())
        .arg("serve")
        .arg("--config")
        .arg(ci_config())
        .args(["--width", "64", "--height", "64", "--ring", &name])
        .arg("--control")
        .arg(&sock_path)
        .arg("--status-file")
        .arg(&status_path)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut r = open_ring(tmp.path(), &name, Duration::from_secs(60));
    let m = next_frame(&mut r);
    assert_eq!((m.width, m.height), (64, 64));
    assert!(m.triangles > 0 && m.fx > 0.0 && m.publish_ns >= m.capture_ns);
    let px = r.pixels();
    assert!(
        px.chunks(4).any(|p| p != &px[..4]),
        "a rendered frame is not uniform"
    );
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(tmp.path().join(&name))
            .unwrap()
            .permissions()
            .mode();
        assert_eq!(mode & 0o777, 0o600);
    }

    // Fuzz for a bounded time; counts must match exactly.
    let sock = UnixDatagram::unbound().unwrap();
    let (mut valid, invalid) = fuzz_control(&sock, &sock_path);
    // A report from a consumer, then a distinctive pose: rendering must go on and use it.
    sock.send_to(
        br#"{"consumer":{"name":"test-reader","received":7,"lost":2}}"#,
        &sock_path,
    )
    .unwrap();
    sock.send_to(
        br#"{"pose":{"position":[1234,4321,2500],"yaw_deg":33,"pitch_deg":-25},"fov_deg":42.5}"#,
        &sock_path,
    )
    .unwrap();
    valid += 2;
    let start = Instant::now();
    loop {
        let m = next_frame(&mut r);
        if m.vfov_deg == 42.5 {
            assert_eq!(m.position, [1234.0, 4321.0, 2500.0]);
            assert_eq!((m.yaw_deg, m.pitch_deg), (33.0, -25.0));
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "pose never applied"
        );
    }

    // Every message was counted: accepted == valid, rejected == invalid.
    let s = status_counting(&status_path, valid + invalid);
    assert_eq!(s["control_accepted"].as_u64(), Some(valid), "{s}");
    assert_eq!(s["control_rejected"].as_u64(), Some(invalid), "{s}");
    assert_eq!(s["state"], "running");
    assert_eq!(s["camera"], "control");
    assert_eq!(s["consumers"]["test-reader"], serde_json::json!([7, 2]));
    assert!(s["frames_rendered"].as_u64().unwrap() > 1);
    let o = exe_in(tmp.path())
        .args(["status", "--status-file"])
        .arg(&status_path)
        .args(["--ring", &name])
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{out}");
    assert!(
        out.contains(&format!("{invalid} rejected"))
            && out.contains("live")
            && out.contains("test-reader"),
        "{out}"
    );

    // Resolution change: a new ring generation at the new size.
    resize_starts_a_new_generation(&sock, &sock_path, &mut r);

    // SIGTERM: frame in flight finished, ring closed, exit 0, nothing left behind.
    let paths = [sock_path.as_path(), &status_path];
    terminate_and_check_clean(child, &mut r, tmp.path(), &name, paths);
}

/// The status file once its accepted and rejected control messages add up to `messages`
/// (within 30 s).
fn status_counting(status_path: &Path, messages: u64) -> serde_json::Value {
    let start = Instant::now();
    loop {
        let s = status_json(status_path);
        if s["control_accepted"].as_u64().unwrap() + s["control_rejected"].as_u64().unwrap()
            == messages
        {
            break s;
        }
        assert!(start.elapsed() < Duration::from_secs(30), "status: {s}");
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// A resolution message starts a new ring generation whose frames have the new size.
fn resize_starts_a_new_generation(sock: &UnixDatagram, sock_path: &Path, r: &mut RingReader) {
    let g1 = r.generation();
    sock.send_to(br#"{"resolution":[48,32]}"#, sock_path)
        .unwrap();
    let start = Instant::now();
    loop {
        match r.wait_next(Duration::from_secs(5)).unwrap() {
            Next::Restarted { generation } => {
                assert_ne!(generation, g1);
                break;
            }
            Next::Closed => panic!("closed instead of restarted"),
            _ => {}
        }
        assert!(start.elapsed() < Duration::from_secs(60), "no restart");
    }
    let m = next_frame(r);
    assert_eq!((m.width, m.height, r.pixels().len()), (48, 32, 48 * 32 * 4));
}

/// Sends random bytes, broken JSON, NaN and absurd values, an oversized datagram and some
/// valid poses in between to the control socket for two seconds: (valid, invalid) sent.
fn fuzz_control(sock: &UnixDatagram, sock_path: &Path) -> (u64, u64) {
    let (mut valid, mut invalid) = (0u64, 0u64);
    let mut x: u64 = 0x1234_5678_9abc_def1;
    let mut rnd = || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let fixed_bad: Vec<Vec<u8>> = [
        "",
        "{",
        "null",
        "[]",
        "{}",
        r#"{"fov_deg": NaN}"#,
        r#"{"fov_deg": 1e999}"#,
        r#"{"fov_deg": 0}"#,
        r#"{"fov_deg": 500}"#,
        r#"{"fov_deg": "wide"}"#,
        r#"{"pose":{"position":[1e308,0,0],"yaw_deg":0,"pitch_deg":0}}"#,
        r#"{"pose":{"position":[0,0,100],"yaw_deg":0,"pitch_deg":95}}"#,
        r#"{"pose":{"position":[0,0],"yaw_deg":0,"pitch_deg":0}}"#,
        r#"{"resolution":[0,0]}"#,
        r#"{"resolution":[100000,2]}"#,
        r#"{"resolution":[-1,64]}"#,
        r#"{"shutdown":true}"#,
        r#"{"consumer":{"name":"","received":1,"lost":0}}"#,
    ]
    .iter()
    .map(|s| s.as_bytes().to_vec())
    .chain([vec![0xff, 0xfe, 0x00], vec![b'{'; 65536]])
    .collect();
    let fuzz_end = Instant::now() + Duration::from_secs(2);
    let mut i = 0usize;
    while Instant::now() < fuzz_end {
        let msg: Vec<u8> = match i % 4 {
            0 => fixed_bad[(i / 4) % fixed_bad.len()].clone(),
            1 => (0..(rnd() % 200)).map(|_| rnd() as u8).collect(),
            2 => {
                // Valid JSON skeleton with a random bad token.
                format!(
                    r#"{{"fov_deg": {}}}"#,
                    ["-1", "1e400", "null", "true"][(rnd() % 4) as usize]
                )
                .into_bytes()
            }
            _ => {
                valid += 1;
                format!(
                    r#"{{"pose":{{"position":[{},{},3000],"yaw_deg":{},"pitch_deg":-30}},"fov_deg":55}}"#,
                    rnd() % 10000,
                    rnd() % 10000,
                    rnd() % 360
                )
                .into_bytes()
            }
        };
        if i % 4 != 3 {
            invalid += 1;
        }
        sock.send_to(&msg, sock_path).unwrap();
        i += 1;
        if i % 64 == 0 {
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    (valid, invalid)
}

/// Sends SIGTERM to `child` (serving ring `name` in `dir`, controlled through `sock_path`) and
/// checks a clean stop: exit 0, the ring closed, no segment, control socket or lock file left,
/// the status file saying "stopped".
fn terminate_and_check_clean(
    child: Child,
    r: &mut RingReader,
    dir: &Path,
    name: &str,
    [sock_path, status_path]: [&Path; 2],
) {
    let pid = child.id();
    // SAFETY: signalling our own child.
    assert_eq!(unsafe { libc::kill(pid as i32, libc::SIGTERM) }, 0);
    let o = wait_exit(child, Duration::from_secs(60));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "stderr: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let start = Instant::now();
    loop {
        match r.wait_next(Duration::from_secs(5)).unwrap() {
            Next::Closed => break,
            Next::Frame(_) => {}
            other => panic!("expected Closed, got {other:?}"),
        }
        assert!(start.elapsed() < Duration::from_secs(10));
    }
    assert_eq!(r.state(), STATE_CLOSED);
    assert!(!dir.join(name).exists(), "segment left behind");
    assert!(!sock_path.exists(), "control socket left behind");
    assert!(
        std::fs::read_dir(dir).unwrap().all(|e| !e
            .unwrap()
            .file_name()
            .to_string_lossy()
            .ends_with(".lock")),
        "lock files left behind"
    );
    assert_eq!(status_json(status_path)["state"], "stopped");
}

#[test]
fn serve_frame_limit_keeps_segment_when_configured() {
    let tmp = tempfile::tempdir().unwrap();
    let name = format!("vkt-keep-{}", std::process::id());
    let rings = tmp.path().join("rings");
    let config = tmp.path().join("keep.toml");
    std::fs::write(
        &config,
        format!(
            "[render]\nwidth = 32\nheight = 24\nreadback_depth = true\n\
             [dataset]\nkind = \"procedural\"\nsize = 129\n\
             [ring]\nname = \"{name}\"\nslots = 3\nkeep_segment = true\ndir = \"rings\"\n"
        ),
    )
    .unwrap();
    let o = exe()
        .arg("serve")
        .arg("--config")
        .arg(&config)
        .args(["--frames", "6"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let seg = rings.join(&name);
    assert!(seg.exists(), "keep_segment = true but the segment is gone");
    let mut r = RingReader::open(&RingLocation::new(&rings, &name).unwrap(), Some(euid())).unwrap();
    assert!(!r.producer_alive(), "the service exited");
    assert_eq!(r.state(), STATE_CLOSED);
    assert_eq!(
        r.latest(),
        Some(5),
        "every frame, the in-flight ones too, is published"
    );
    let Next::Frame(m) = r.wait_next(Duration::from_secs(1)).unwrap() else {
        panic!("no frame in a kept ring");
    };
    assert_eq!((m.frame, m.width, m.height), (5, 32, 24));
    let depth = r.depth().expect("depth in the ring");
    assert!(depth.iter().all(|d| (0.0..=1.0).contains(d)));
    assert!(depth.iter().any(|&d| d > 0.0), "terrain in view");
    assert_eq!(r.wait_next(Duration::from_secs(1)).unwrap(), Next::Closed);
}

#[test]
fn serve_bad_input_is_one_line() {
    let tmp = tempfile::tempdir().unwrap();
    let bad_slots = tmp.path().join("slots.toml");
    std::fs::write(&bad_slots, "[ring]\nslots = 1\n").unwrap();
    let bad_key = tmp.path().join("key.toml");
    std::fs::write(&bad_key, "[service]\ncontrl = \"x\"\n").unwrap();
    let not_socket = tmp.path().join("file");
    std::fs::write(&not_socket, "x").unwrap();
    let big = tmp.path().join("big.json");
    std::fs::write(&big, vec![b' '; (1 << 20) + 10]).unwrap();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["serve".into(), "--ring".into(), "../etc".into()],
            "ring name",
        ),
        (
            vec![
                "serve".into(),
                "--config".into(),
                bad_slots.display().to_string(),
            ],
            "ring.slots",
        ),
        (
            vec![
                "serve".into(),
                "--config".into(),
                bad_key.display().to_string(),
            ],
            "contrl",
        ),
        (
            vec![
                "serve".into(),
                "--config".into(),
                ci_config().display().to_string(),
                "--ring".into(),
                format!("vkt-badsock-{}", std::process::id()),
                "--control".into(),
                not_socket.display().to_string(),
            ],
            "not a socket",
        ),
        (vec!["status".into()], "--status-file"),
        // A device is no status file: refused at once, never read without bound.
        (
            vec!["status".into(), "--status-file".into(), "/dev/zero".into()],
            "not a regular file",
        ),
        (
            vec![
                "status".into(),
                "--status-file".into(),
                big.display().to_string(),
            ],
            "larger than",
        ),
        // And never replaced by a status file.
        (
            vec![
                "serve".into(),
                "--config".into(),
                ci_config().display().to_string(),
                "--status-file".into(),
                "/dev/null".into(),
            ],
            "not a regular file",
        ),
        (
            vec![
                "status".into(),
                "--status-file".into(),
                "/nonexistent/s.json".into(),
            ],
            "/nonexistent/s.json",
        ),
        (
            vec!["status".into(), "--ring".into(), "vkt-no-such-ring".into()],
            "vkt-no-such-ring",
        ),
    ];
    for (args, word) in cases {
        let o = exe().args(&args).output().unwrap();
        common::cli::assert_one_line_error(&o, &[word]);
    }
    assert_eq!(
        std::fs::read(&not_socket).unwrap(),
        b"x",
        "a non-socket was replaced"
    );
    assert!(
        !Path::new("/nonexistent-ring-dir")
            .join(format!("vkt-badsock-{}", std::process::id()))
            .exists()
    );
}

#[test]
fn serve_streams_through_the_clipmap_with_two_views() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("ds");
    let o = exe()
        .args([
            "preprocess",
            "--procedural",
            "--size",
            "257",
            "--node-size",
            "32",
            "--out",
        ])
        .arg(&data)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let name = format!("vkt-clip-{}", std::process::id());
    let rings = tmp.path().join("rings");
    let config = tmp.path().join("clip.toml");
    std::fs::write(
        &config,
        format!(
            "[render]\nwidth = 64\nheight = 24\nreadback_depth = true\n\
             [[render.extra_views]]\nyaw_deg = 180.0\n\
             [dataset]\nkind = \"tiles\"\npath = {:?}\n\
             [clipmap]\nenabled = true\natlas_capacity = 40\nnode_count = 4\n\
             [ring]\nname = \"{name}\"\nslots = 3\nkeep_segment = true\ndir = \"rings\"\n",
            data.display().to_string()
        ),
    )
    .unwrap();
    let status = tmp.path().join("status.json");
    let o = exe()
        .arg("serve")
        .arg("--config")
        .arg(&config)
        .args(["--frames", "6", "--status-file"])
        .arg(&status)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = status_json(&status);
    assert_eq!(s["state"], "stopped");
    let c = &s["clipmap"];
    assert_eq!(c["atlas_capacity"], 40, "{s}");
    assert!(c["loaded"].as_u64().unwrap() > 0, "{s}");
    assert!(c["resident_nodes"].as_u64().unwrap() <= 40, "{s}");
    assert_eq!(c["load_errors"], 0, "{s}");
    // The ring's frames hold both views side by side, terrain in each.
    let mut r = RingReader::open(&RingLocation::new(&rings, &name).unwrap(), Some(euid())).unwrap();
    let Next::Frame(m) = r.wait_next(Duration::from_secs(1)).unwrap() else {
        panic!("no frame in a kept ring");
    };
    assert_eq!((m.frame, m.width, m.height), (5, 64, 24));
    let depth = r.depth().expect("depth in the ring");
    for half in [0..32usize, 32..64] {
        assert!(
            (0..24).any(|y| half.clone().any(|x| depth[y * 64 + x] > 0.0)),
            "no terrain in columns {half:?}"
        );
    }
}

fn spawn_serve(dir: &Path, name: &str, extra: &[&str]) -> Child {
    exe_in(dir)
        .arg("serve")
        .arg("--config")
        .arg(ci_config())
        .args(["--width", "32", "--height", "32", "--ring", name])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn wait_status(
    path: &Path,
    what: &str,
    ok: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let start = Instant::now();
    loop {
        if let Ok(text) = std::fs::read_to_string(path)
            && let Ok(s) = serde_json::from_str::<serde_json::Value>(&text)
            && ok(&s)
        {
            return s;
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "{what}: {path:?}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn second_service_cannot_take_over_socket_status_or_ring() {
    let tmp = tempfile::tempdir().unwrap();
    let sock = tmp.path().join("control.sock");
    let status = tmp.path().join("status.json");
    let (s, st) = (sock.display().to_string(), status.display().to_string());
    let first = spawn_serve(
        tmp.path(),
        "first",
        &["--control", &s, "--status-file", &st],
    );
    let mut r = open_ring(tmp.path(), "first", Duration::from_secs(60));
    next_frame(&mut r);
    wait_status(&status, "first status", |v| v["state"] == "running");
    // A second service on the same socket, the same status file, or the same ring: refused
    // with one line naming the owner; the first keeps its socket and its status.
    for (args, what) in [
        (vec!["--control", &s], "control socket"),
        (vec!["--status-file", &st], "status file"),
    ] {
        let o = exe_in(tmp.path())
            .arg("serve")
            .arg("--config")
            .arg(ci_config())
            .args(["--ring", "second", "--frames", "2"])
            .args(&args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{what}: {err}");
        assert!(
            err.contains("in use by a live process") && err.lines().count() == 1,
            "{what}: {err}"
        );
    }
    let o = exe_in(tmp.path())
        .arg("serve")
        .arg("--config")
        .arg(ci_config())
        .args(["--ring", "first", "--frames", "2"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("in use by a live process"), "{err}");
    // The first service still listens: a pose sent now is rendered.
    let c = UnixDatagram::unbound().unwrap();
    c.send_to(
        br#"{"pose":{"position":[100,200,900],"yaw_deg":10,"pitch_deg":-20},"fov_deg":33}"#,
        &sock,
    )
    .unwrap();
    let start = Instant::now();
    while next_frame(&mut r).vfov_deg != 33.0 {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the first service went deaf"
        );
    }
    // Negative control: once the owner is gone (killed: its socket, lock files, status and
    // ring stay behind), the same paths are free.
    let mut first = first;
    first.kill().unwrap();
    let _ = first.wait();
    assert!(sock.exists() && tmp.path().join("first").exists());
    let o = exe_in(tmp.path())
        .arg("serve")
        .arg("--config")
        .arg(ci_config())
        .args([
            "--width", "32", "--height", "32", "--ring", "first", "--frames", "2",
        ])
        .args(["--control", &s, "--status-file", &st])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

fn roles() -> Command {
    Command::new(env!("CARGO_BIN_EXE_vkterrain-test-roles"))
}

#[test]
fn dead_consumers_give_their_slots_back_and_status_sees_stale_rings() {
    let tmp = tempfile::tempdir().unwrap();
    let sock = tmp.path().join("control.sock");
    let status = tmp.path().join("status.json");
    let (s, st) = (sock.display().to_string(), status.display().to_string());
    let serve = spawn_serve(
        tmp.path(),
        "reclaim",
        &["--control", &s, "--status-file", &st],
    );
    let mut r = open_ring(tmp.path(), "reclaim", Duration::from_secs(60));
    next_frame(&mut r);
    // A live process fills all 64 consumer entries: the next registration is rejected.
    let mut filler = roles()
        .args(["register", &format!("sock={s}"), "count=64"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    use std::io::BufRead;
    std::io::BufReader::new(filler.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert!(line.contains("sent=64"), "{line}");
    wait_status(&status, "64 consumers", |v| {
        v["consumers"].as_object().is_some_and(|c| c.len() == 64)
    });
    let c = UnixDatagram::unbound().unwrap();
    let mine = br#"{"consumer":{"name":"late","received":5,"lost":1}}"#;
    c.send_to(mine, &sock).unwrap();
    let v = wait_status(&status, "rejected registration", |v| {
        v["control_rejected"].as_u64() == Some(1)
    });
    assert!(v["consumers"].get("late").is_none(), "{v}");
    // The filler exits: its entries are reclaimed and the same registration is accepted.
    drop(filler.stdin.take());
    filler.wait().unwrap();
    c.send_to(mine, &sock).unwrap();
    let v = wait_status(&status, "reclaimed", |v| {
        v["consumers"].get("late").is_some()
    });
    assert_eq!(v["consumers"]["late"], serde_json::json!([5, 1]));
    assert_eq!(v["consumers"].as_object().unwrap().len(), 1, "{v}");

    // A killed service leaves its ring "live" in the state word; `status` says stale.
    let mut serve = serve;
    serve.kill().unwrap();
    let _ = serve.wait();
    let o = exe_in(tmp.path())
        .args(["status", "--ring", "reclaim"])
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.contains("stale (its producer is gone)"), "{out}");
    let o = exe_in(tmp.path())
        .args(["status", "--status-file", &st])
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("dead (process gone"), "{out}");
}

#[test]
fn failed_status_write_leaves_no_temporary_file() {
    let tmp = tempfile::tempdir().unwrap();
    let target = tmp.path().join("status.json");
    // RLIMIT_FSIZE stands in for a full disk: the write fails part way.
    let o = roles()
        .args(["efbig", &format!("path={}", target.display())])
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("failed=1"), "{out}");
    let left: Vec<_> = std::fs::read_dir(tmp.path()).unwrap().collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

#[test]
fn serve_publishes_zero_copy_where_the_device_can() {
    // lavapipe (CI) offers VK_EXT_external_memory_host: the GPU writes into the ring slots.
    let tmp = tempfile::tempdir().unwrap();
    let status = tmp.path().join("status.json");
    let config = tmp.path().join("zc.toml");
    std::fs::write(
        &config,
        "[render]\nwidth = 48\nheight = 32\nframes_in_flight = 2\n[dataset]\nkind = \"procedural\"\nsize = 129\n\
         [ring]\nname = \"zc\"\nslots = 3\nkeep_segment = true\n",
    )
    .unwrap();
    let o = exe_in(tmp.path())
        .arg("serve")
        .arg("--config")
        .arg(&config)
        .args(["--frames", "8", "--status-file"])
        .arg(&status)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = status_json(&status);
    let info = exe().arg("info").output().unwrap();
    let offered = String::from_utf8_lossy(&info.stdout)
        .lines()
        .any(|l| l.contains("external memory host") && l.contains("yes /"));
    assert_eq!(s["zero_copy"].as_bool(), Some(offered), "{s}");
    let mut r =
        RingReader::open(&RingLocation::new(tmp.path(), "zc").unwrap(), Some(euid())).unwrap();
    let Next::Frame(m) = r.wait_next(Duration::from_secs(1)).unwrap() else {
        panic!("no frame");
    };
    assert_eq!((m.frame, m.width, m.height), (7, 48, 32));
    let px = r.pixels();
    assert!(px.chunks(4).any(|p| p != &px[..4]), "an empty frame");
    // Fallback: with as many slots as frames in flight zero-copy is refused and says why;
    // frames are copied instead.
    std::fs::write(
        &config,
        "[render]\nwidth = 48\nheight = 32\nframes_in_flight = 2\n[dataset]\nkind = \"procedural\"\nsize = 129\n\
         [ring]\nname = \"zc2\"\nslots = 2\n",
    )
    .unwrap();
    let o = exe_in(tmp.path())
        .arg("serve")
        .arg("--config")
        .arg(&config)
        .args(["--frames", "4", "--status-file"])
        .arg(&status)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s = status_json(&status);
    assert_eq!(s["zero_copy"].as_bool(), Some(false), "{s}");
    if offered {
        assert!(
            s["zero_copy_note"].as_str().unwrap().contains("more slots"),
            "{s}"
        );
    }
    assert_eq!(s["frames_rendered"], 4);
}

/// A config like ci.toml, anchored on the earth, with `scenario` as its flight.
fn anchored_config(dir: &Path, scenario: &str) -> PathBuf {
    let scenario_path = dir.join("geo.toml");
    std::fs::write(&scenario_path, scenario).unwrap();
    let config = dir.join("anchored.toml");
    std::fs::write(
        &config,
        format!(
            "[render]\nwidth = 64\nheight = 64\n\
             [dataset]\nkind = \"procedural\"\nsize = 513\nseed = 1\nspacing = 60.0\n\
             anchor = {{ lat_deg = 46.5, lon_deg = 8.0 }}\n\
             [method]\nname = \"brute\"\n\
             [scenario]\npath = {:?}\n\
             [output]\ndir = {:?}\npng_frames = [0]\n",
            scenario_path.display().to_string(),
            dir.join("out").display().to_string()
        ),
    )
    .unwrap();
    config
}

/// The same WGS84 pose as a scenario keyframe (`render`) and as a control message (`serve`)
/// gives the same pixels; the ring reports the pose back. Negative control: serve's scripted
/// frame before the message differs.
#[test]
fn wgs84_pose_sent_to_serve_renders_like_the_same_pose_in_a_scenario() {
    let tmp = tempfile::tempdir().unwrap();
    let (lat, lon, agl, heading, pitch) = (46.6, 8.12, 1500.0, 210.0, -20.0);
    let keyframe = format!(
        "name = \"geo\"\nframes = 1\nvfov_deg = 42.5\n[[keyframe]]\nt = 0.0\n\
         lat_deg = {lat}\nlon_deg = {lon}\nheight_m = {agl}\nheight_ref = \"ground\"\n\
         heading_deg = {heading}\npitch_deg = {pitch}\n"
    );
    let config = anchored_config(tmp.path(), &keyframe);
    let out = common::cli::command()
        .args(["render", "--frames", "1", "--config"])
        .arg(&config)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let want = image::open(tmp.path().join("out/frame_00000.png"))
        .unwrap()
        .to_rgba8();

    // serve flies the default scenario until the message arrives.
    let served = anchored_config(
        tmp.path(),
        "name = \"d\"\nframes = 10\n[[keyframe]]\nt = 0.0\nposition = [9000.0, 9000.0, 4000.0]\nyaw = 45.0\npitch = -30.0\n",
    );
    let name = format!("vkt-geo-{}", std::process::id());
    let sock_path = tmp.path().join("control.sock");
    let child = exe_in(tmp.path())
        .arg("serve")
        .arg("--config")
        .arg(&served)
        .args(["--ring", &name, "--control"])
        .arg(&sock_path)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut r = open_ring(tmp.path(), &name, Duration::from_secs(60));
    let first = next_frame(&mut r);
    assert_eq!(
        first.height_datum,
        vkterrain::output::ring::layout::DATUM_ELLIPSOID
    );
    let scripted = r.pixels().to_vec();
    assert_ne!(
        scripted,
        want.as_raw().as_slice(),
        "negative control: another pose"
    );
    let msg = format!(
        r#"{{"pose":{{"lat_deg":{lat},"lon_deg":{lon},"height_m":{agl},"height_ref":"ground","heading_deg":{heading},"pitch_deg":{pitch}}},"fov_deg":42.5}}"#
    );
    UnixDatagram::unbound()
        .unwrap()
        .send_to(msg.as_bytes(), &sock_path)
        .unwrap();
    let start = Instant::now();
    let m = loop {
        let m = next_frame(&mut r);
        if m.vfov_deg == 42.5 {
            break m;
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "pose never applied"
        );
    };
    assert_eq!(
        r.pixels(),
        want.as_raw().as_slice(),
        "control pose != scenario pose"
    );
    // The ring reports the camera on the earth.
    assert!(
        (m.lat_deg - lat).abs() < 1e-9 && (m.lon_deg - lon).abs() < 1e-9,
        "{m:?}"
    );
    assert!((m.heading_deg - heading).abs() < 1e-6 && (m.local_pitch_deg - pitch).abs() < 1e-6);
    assert!(
        m.height_m.is_finite() && m.height_datum == first.height_datum,
        "{m:?}"
    );
    // A WGS84 pose outside the data set (no ground) is rejected, rendering goes on.
    UnixDatagram::unbound()
        .unwrap()
        .send_to(
            br#"{"pose":{"lat_deg":10,"lon_deg":8,"height_m":5,"height_ref":"ground","heading_deg":0,"pitch_deg":0}}"#,
            &sock_path,
        )
        .unwrap();
    next_frame(&mut r);
    // SAFETY: signalling our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let o = wait_exit(child, Duration::from_secs(60));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}
