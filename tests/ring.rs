//! The shared-memory ring across processes: the C header matches the Rust layout, frames round
//! trip with their metadata, four consumers (Rust, C, Python) read a producer that publishes as
//! fast as it can without ever accepting a torn frame, a killed consumer harms nobody, and a
//! killed and restarted producer is picked up.
//!
//! Producers and Rust consumers run as child processes of this test binary (`role_process`,
//! selected by `VKT_RING_ROLE`), so every test is multi-process.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use vkterrain::output::ring::layout::{self, FrameMeta, RingHeader, SlotHeader};
use vkterrain::output::ring::{Geometry, Next, ProducerOptions, RingProducer, RingReader};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A ring name unique to this test run.
fn ring_name(tag: &str) -> String {
    format!("vkt-test-{tag}-{}", std::process::id())
}

/// The test pattern: frame number in bytes 0..8, CRC-32 of bytes 16.. in bytes 8..12, the rest
/// pseudo-random per frame (so two frames never agree on a checksum by accident).
fn pattern(frame: u64, buf: &mut [u8]) {
    let mut x = frame.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    for chunk in buf[16..].chunks_mut(8) {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        let b = x.to_le_bytes();
        chunk.copy_from_slice(&b[..chunk.len()]);
    }
    let crc = crc32fast::hash(&buf[16..]);
    buf[..8].copy_from_slice(&frame.to_le_bytes());
    buf[8..12].copy_from_slice(&crc.to_le_bytes());
    buf[12..16].fill(0);
}

fn pattern_ok(frame: u64, buf: &[u8]) -> bool {
    buf.len() >= 16
        && buf[..8] == frame.to_le_bytes()
        && buf[8..12] == crc32fast::hash(&buf[16..]).to_le_bytes()
}

fn test_meta(g: Geometry) -> FrameMeta {
    FrameMeta {
        width: g.width,
        height: g.height,
        position: [1.0, 2.0, 3.0],
        vfov_deg: 60.0,
        ..Default::default()
    }
}

/// Child-process roles. Does nothing unless `VKT_RING_ROLE` is set.
#[test]
fn role_process() {
    let Ok(role) = std::env::var("VKT_RING_ROLE") else {
        return;
    };
    let name = std::env::var("VKT_RING_NAME").unwrap();
    let seconds: f64 = std::env::var("VKT_RING_SECONDS").unwrap().parse().unwrap();
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    match role.as_str() {
        "producer" => {
            let side: u32 = std::env::var("VKT_RING_SIDE").map_or(64, |s| s.parse().unwrap());
            let g = Geometry {
                width: side,
                height: side,
                slot_count: 4,
                depth: false,
            };
            let corrupt = std::env::var("VKT_RING_CORRUPT").is_ok();
            let mut p = RingProducer::create(&name, g, &ProducerOptions::default()).unwrap();
            let mut buf = vec![0u8; g.pixel_bytes() as usize];
            let meta = test_meta(g);
            while Instant::now() < end {
                pattern(p.published(), &mut buf);
                if corrupt {
                    buf[20] ^= 0xff;
                }
                p.publish(&meta, &buf, None).unwrap();
                if corrupt {
                    std::thread::sleep(Duration::from_millis(5));
                }
            }
            println!("published={}", p.published());
        }
        "consumer" => {
            let mut r = RingReader::open_wait(&name, Duration::from_secs(5)).unwrap();
            let (mut bad, mut nonincreasing, mut gaps, mut closed) = (0u64, 0u64, 0u64, 0);
            let mut prev: Option<u64> = None;
            while Instant::now() < end {
                match r.wait_next(Duration::from_secs(5)).unwrap() {
                    Next::Frame(m) => {
                        if let Some(p) = prev {
                            if m.frame <= p {
                                nonincreasing += 1;
                            } else {
                                gaps += m.frame - p - 1;
                            }
                        }
                        prev = Some(m.frame);
                        if !pattern_ok(m.frame, r.pixels()) {
                            bad += 1;
                        }
                    }
                    Next::Restarted { .. } => prev = None,
                    Next::Closed => {
                        closed = 1;
                        break;
                    }
                    Next::Timeout => {}
                }
            }
            let s = r.stats();
            println!(
                "received={} lost={} gaps={gaps} bad={bad} nonincreasing={nonincreasing} torn_retries={} restarts={} closed={closed}",
                s.received, s.lost, s.torn_retries, s.restarts
            );
        }
        other => panic!("unknown role {other}"),
    }
}

fn spawn_role(role: &str, name: &str, seconds: f64, extra: &[(&str, &str)]) -> Child {
    let mut c = Command::new(std::env::current_exe().unwrap());
    c.args(["--exact", "role_process", "--nocapture", "--test-threads=1"])
        .env("VKT_RING_ROLE", role)
        .env("VKT_RING_NAME", name)
        .env("VKT_RING_SECONDS", seconds.to_string())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    for (k, v) in extra {
        c.env(k, v);
    }
    c.spawn().unwrap()
}

/// The C example, compiled once per test into `dir`.
fn build_c(dir: &Path) -> PathBuf {
    let exe = dir.join("ring_reader");
    let src = root().join("consumers/c/ring_reader.c");
    let o = Command::new("cc")
        .args(["-O2", "-std=c11", "-Wall", "-Wextra", "-Werror", "-o"])
        .arg(&exe)
        .arg(&src)
        .output()
        .expect("the system C compiler `cc` (apt-get install gcc)");
    assert!(
        o.status.success(),
        "cc failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    exe
}

fn python() -> Option<&'static str> {
    let ok = Command::new("python3")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        eprintln!("SKIPPING the Python consumer: python3 is not installed");
    }
    ok.then_some("python3")
}

fn spawn_c(exe: &Path, name: &str, seconds: f64) -> Child {
    Command::new(exe)
        .args([name, "--verify", "--seconds", &seconds.to_string()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn spawn_py(py: &str, name: &str, seconds: f64, save: Option<&Path>) -> Child {
    let mut c = Command::new(py);
    c.arg(root().join("consumers/python/vkterrain_ring.py"))
        .args([name, "--verify", "--seconds", &seconds.to_string()]);
    if let Some(s) = save {
        c.arg("--save").arg(s);
    }
    c.stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Waits for a child and parses its `key=value` counter line.
fn counters(child: Child, who: &str) -> BTreeMap<String, u64> {
    let o = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{who} failed: {stdout}\n{stderr}");
    // The line may follow the test harness's `test role_process ... ` on the same line.
    let line = stdout
        .lines()
        .find_map(|l| {
            l.find("received=")
                .or_else(|| l.find("published="))
                .map(|i| &l[i..])
        })
        .unwrap_or_else(|| panic!("{who} printed no counters: {stdout}\n{stderr}"));
    line.split_whitespace()
        .filter_map(|kv| kv.split_once('='))
        .map(|(k, v)| (k.to_string(), v.parse().unwrap()))
        .collect()
}

fn assert_clean(c: &BTreeMap<String, u64>, who: &str, min_received: u64) {
    assert_eq!(c["bad"], 0, "{who} accepted torn/corrupt frames: {c:?}");
    assert_eq!(
        c["nonincreasing"], 0,
        "{who}: frame numbers went backwards: {c:?}"
    );
    assert_eq!(
        c["lost"], c["gaps"],
        "{who}: reported losses != observed gaps: {c:?}"
    );
    assert!(
        c["received"] >= min_received,
        "{who} received too few frames: {c:?}"
    );
}

#[test]
fn c_header_and_python_match_rust_layout() {
    use std::mem::{offset_of, size_of};
    let mut want: BTreeMap<String, usize> = BTreeMap::new();
    macro_rules! off {
        ($c:literal, $t:ty, $($f:tt)+) => {
            want.insert(format!("{}.{}", $c, stringify!($($f)+)), offset_of!($t, $($f)+));
        };
    }
    want.insert("vkt_ring_header.size".into(), size_of::<RingHeader>());
    off!("vkt_ring_header", RingHeader, magic);
    off!("vkt_ring_header", RingHeader, layout_version);
    off!("vkt_ring_header", RingHeader, header_size);
    off!("vkt_ring_header", RingHeader, generation);
    off!("vkt_ring_header", RingHeader, width);
    off!("vkt_ring_header", RingHeader, height);
    off!("vkt_ring_header", RingHeader, pixel_format);
    off!("vkt_ring_header", RingHeader, row_stride);
    off!("vkt_ring_header", RingHeader, slot_count);
    off!("vkt_ring_header", RingHeader, depth_format);
    off!("vkt_ring_header", RingHeader, slot_size);
    off!("vkt_ring_header", RingHeader, pixels_offset);
    off!("vkt_ring_header", RingHeader, depth_offset);
    off!("vkt_ring_header", RingHeader, producer_pid);
    off!("vkt_ring_header", RingHeader, latest);
    off!("vkt_ring_header", RingHeader, state);
    off!("vkt_ring_header", RingHeader, wake);
    off!("vkt_ring_header", RingHeader, published);
    want.insert("vkt_slot_header.size".into(), size_of::<SlotHeader>());
    off!("vkt_slot_header", SlotHeader, seq);
    off!("vkt_slot_header", SlotHeader, meta);
    want.insert("vkt_frame_meta.size".into(), size_of::<FrameMeta>());
    for (c, r) in [
        ("frame", offset_of!(FrameMeta, frame)),
        ("capture_ns", offset_of!(FrameMeta, capture_ns)),
        ("publish_ns", offset_of!(FrameMeta, publish_ns)),
        ("width", offset_of!(FrameMeta, width)),
        ("height", offset_of!(FrameMeta, height)),
        ("row_stride", offset_of!(FrameMeta, row_stride)),
        ("position", offset_of!(FrameMeta, position)),
        ("yaw_deg", offset_of!(FrameMeta, yaw_deg)),
        ("pitch_deg", offset_of!(FrameMeta, pitch_deg)),
        ("roll_deg", offset_of!(FrameMeta, roll_deg)),
        ("vfov_deg", offset_of!(FrameMeta, vfov_deg)),
        ("near_m", offset_of!(FrameMeta, near)),
        ("far_m", offset_of!(FrameMeta, far)),
        ("fx", offset_of!(FrameMeta, fx)),
        ("fy", offset_of!(FrameMeta, fy)),
        ("cx", offset_of!(FrameMeta, cx)),
        ("cy", offset_of!(FrameMeta, cy)),
        ("gpu_prepass_ms", offset_of!(FrameMeta, gpu_prepass_ms)),
        ("gpu_terrain_ms", offset_of!(FrameMeta, gpu_terrain_ms)),
        ("gpu_readback_ms", offset_of!(FrameMeta, gpu_readback_ms)),
        ("cpu_record_ms", offset_of!(FrameMeta, cpu_record_ms)),
        ("cpu_wait_ms", offset_of!(FrameMeta, cpu_wait_ms)),
        ("triangles", offset_of!(FrameMeta, triangles)),
    ] {
        want.insert(format!("vkt_frame_meta.{c}"), r);
    }

    let tmp = tempfile::tempdir().unwrap();
    let exe = build_c(tmp.path());
    let o = Command::new(&exe).arg("--layout").output().unwrap();
    assert!(o.status.success());
    let got: BTreeMap<String, usize> = String::from_utf8_lossy(&o.stdout)
        .lines()
        .filter_map(|l| l.split_once(' '))
        .map(|(k, v)| (k.to_string(), v.parse().unwrap()))
        .collect();
    assert_eq!(got, want, "C header layout differs from the Rust layout");

    // The Python module's offsets and metadata format.
    if let Some(py) = python() {
        let script = format!(
            "import sys; sys.path.insert(0, {:?}); import vkterrain_ring as v; \
             print(v.HEADER_SIZE, v.H_GENERATION, v.H_SLOT_SIZE, v.H_PIXELS_OFFSET, v.H_PID, \
             v.H_LATEST, v.H_STATE, v.H_WAKE, v.H_PUBLISHED, v.S_META, v.META_SIZE, v.MAGIC, \
             __import__('struct').calcsize(v.META_FORMAT[:-1]))",
            root().join("consumers/python").display().to_string()
        );
        let o = Command::new(py).args(["-c", &script]).output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let got: Vec<u64> = String::from_utf8_lossy(&o.stdout)
            .split_whitespace()
            .map(|v| v.parse().unwrap())
            .collect();
        let want = vec![
            size_of::<RingHeader>() as u64,
            offset_of!(RingHeader, generation) as u64,
            offset_of!(RingHeader, slot_size) as u64,
            offset_of!(RingHeader, pixels_offset) as u64,
            offset_of!(RingHeader, producer_pid) as u64,
            offset_of!(RingHeader, latest) as u64,
            offset_of!(RingHeader, state) as u64,
            offset_of!(RingHeader, wake) as u64,
            offset_of!(RingHeader, published) as u64,
            offset_of!(SlotHeader, meta) as u64,
            size_of::<FrameMeta>() as u64,
            layout::MAGIC,
            offset_of!(FrameMeta, triangles) as u64,
        ];
        assert_eq!(got, want, "Python offsets differ from the Rust layout");
    }
}

#[test]
fn round_trip_metadata_timeout_view_close_and_permissions() {
    use std::os::unix::fs::PermissionsExt;
    let name = ring_name("rt");
    let g = Geometry {
        width: 8,
        height: 4,
        slot_count: 3,
        depth: true,
    };
    let mut p = RingProducer::create(&name, g, &ProducerOptions::default()).unwrap();
    let path = Path::new("/dev/shm").join(&name);
    let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o600, "segment mode");

    let mut r = RingReader::open(&name).unwrap();
    assert_eq!(r.geometry(), g);
    assert_eq!(r.generation(), p.generation());
    assert_eq!(
        r.wait_next(Duration::from_millis(50)).unwrap(),
        Next::Timeout
    );
    assert!(r.view().is_none());

    let depth: Vec<f32> = (0..32).map(|i| i as f32 / 32.0).collect();
    let mut px = vec![0u8; g.pixel_bytes() as usize];
    for f in 0..5u64 {
        pattern(f, &mut px);
        let mut m = test_meta(g);
        m.capture_ns = 1000 + f;
        m.triangles = 77;
        p.publish(&m, &px, Some(&depth)).unwrap();
    }
    let Next::Frame(m) = r.wait_next(Duration::from_secs(1)).unwrap() else {
        panic!("expected a frame");
    };
    assert_eq!(m.frame, 4, "a reader gets the newest frame");
    assert_eq!(
        (m.capture_ns, m.triangles, m.position),
        (1004, 77, [1.0, 2.0, 3.0])
    );
    assert!(m.publish_ns >= m.capture_ns);
    assert!(pattern_ok(4, r.pixels()));
    assert_eq!(r.depth().unwrap(), &depth[..]);
    {
        let v = r.view().unwrap();
        assert_eq!(v.meta.frame, 4);
        assert!(pattern_ok(4, v.pixels()) && v.is_valid());
        // Overwrite the slot holding frame 4 (3 slots: frame 7): the view must notice.
        for f in 5..8u64 {
            pattern(f, &mut px);
            p.publish(&test_meta(g), &px, Some(&depth)).unwrap();
        }
        assert!(!v.is_valid(), "an overwritten view must report invalid");
    }
    let Next::Frame(m) = r.wait_next(Duration::from_secs(1)).unwrap() else {
        panic!("expected a frame");
    };
    assert_eq!((m.frame, r.stats().lost, r.stats().received), (7, 2, 2));

    // Wrong sizes are errors, not panics.
    assert!(p.publish(&test_meta(g), &px[1..], Some(&depth)).is_err());
    assert!(p.publish(&test_meta(g), &px, None).is_err());

    p.close();
    assert_eq!(r.wait_next(Duration::from_secs(5)).unwrap(), Next::Closed);
    assert!(!path.exists(), "segment left behind after close");
    assert!(RingReader::open(&name).is_err());
}

#[test]
fn names_and_live_producers_are_checked() {
    let g = Geometry {
        width: 4,
        height: 4,
        slot_count: 2,
        depth: false,
    };
    for bad in ["", "a/b", "..", ".hidden", "sp ace", &"x".repeat(201), "ü"] {
        let e = RingProducer::create(bad, g, &ProducerOptions::default())
            .err()
            .unwrap_or_else(|| panic!("{bad:?} accepted"));
        assert!(e.to_string().contains("ring name"), "{e}");
        assert!(RingReader::open(bad).is_err());
    }
    for (w, slots) in [(0, 2), (4, 1), (4, 65), (20000, 2)] {
        let g = Geometry {
            width: w,
            height: 4,
            slot_count: slots,
            depth: false,
        };
        assert!(RingProducer::create(&ring_name("geom"), g, &ProducerOptions::default()).is_err());
    }
    // A segment whose producer is alive (pid 1 here) is refused; not-a-ring files are rejected
    // by readers with one line.
    let name = ring_name("live");
    let p = RingProducer::create(&name, g, &ProducerOptions::default()).unwrap();
    let path = Path::new("/dev/shm").join(&name);
    {
        use std::os::unix::fs::FileExt;
        let f = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
        f.write_all_at(&1u32.to_le_bytes(), 60).unwrap();
    }
    let e = RingProducer::create(&name, g, &ProducerOptions::default())
        .err()
        .expect("replaced a live producer");
    assert!(e.to_string().contains("in use"), "{e}");
    drop(p);
    let junk = ring_name("junk");
    let jp = Path::new("/dev/shm").join(&junk);
    std::fs::File::create(&jp)
        .unwrap()
        .write_all(&[7u8; 512])
        .unwrap();
    let e = RingReader::open(&junk).err().expect("junk accepted");
    assert!(
        e.to_string().contains("magic") && !e.to_string().contains('\n'),
        "{e}"
    );
    // A stale non-ring file under the name is replaced by a producer.
    let p = RingProducer::create(&junk, g, &ProducerOptions::default()).unwrap();
    assert!(RingReader::open(&junk).is_ok());
    drop(p);
    assert!(!jp.exists());
}

#[test]
fn stress_four_consumers_rust_c_python() {
    let name = ring_name("stress");
    let tmp = tempfile::tempdir().unwrap();
    let c_exe = build_c(tmp.path());
    let secs = 3.0;
    let producer = spawn_role("producer", &name, secs + 1.0, &[]);
    std::thread::sleep(Duration::from_millis(300));
    let r1 = spawn_role("consumer", &name, secs, &[]);
    let r2 = spawn_role("consumer", &name, secs, &[]);
    let c = spawn_c(&c_exe, &name, secs);
    let png = tmp.path().join("py.png");
    let py = python().map(|py| spawn_py(py, &name, secs, Some(&png)));
    for (child, who) in [
        (r1, "rust consumer 1"),
        (r2, "rust consumer 2"),
        (c, "C consumer"),
    ] {
        let k = counters(child, who);
        eprintln!("{who}: {k:?}");
        assert_clean(&k, who, 50);
    }
    if let Some(py) = py {
        let k = counters(py, "Python consumer");
        eprintln!("Python consumer: {k:?}");
        assert_clean(&k, "Python consumer", 20);
        assert!(
            std::fs::read(&png).unwrap().starts_with(b"\x89PNG"),
            "Python consumer saved no PNG"
        );
    }
    let p = counters(producer, "producer");
    eprintln!("producer: {p:?}");
    assert!(p["published"] > 500, "producer too slow: {p:?}");
}

#[test]
fn verifiers_detect_corrupt_frames() {
    // The checksum check the stress test relies on must be able to fail.
    let name = ring_name("corrupt");
    let tmp = tempfile::tempdir().unwrap();
    let c_exe = build_c(tmp.path());
    let producer = spawn_role("producer", &name, 1.5, &[("VKT_RING_CORRUPT", "1")]);
    std::thread::sleep(Duration::from_millis(200));
    let r = spawn_role("consumer", &name, 1.0, &[]);
    let c = spawn_c(&c_exe, &name, 1.0);
    let py = python().map(|py| spawn_py(py, &name, 1.0, None));
    let mut all = vec![(counters(r, "rust"), "rust"), (counters(c, "C"), "C")];
    if let Some(py) = py {
        all.push((counters(py, "python"), "python"));
    }
    for (k, who) in all {
        assert!(
            k["received"] > 0 && k["bad"] == k["received"],
            "{who}: {k:?}"
        );
    }
    counters(producer, "producer");
}

#[test]
fn killed_consumer_does_not_affect_producer_or_others() {
    let name = ring_name("kill");
    let tmp = tempfile::tempdir().unwrap();
    let c_exe = build_c(tmp.path());
    let producer = spawn_role("producer", &name, 3.0, &[]);
    std::thread::sleep(Duration::from_millis(300));
    let survivor = spawn_role("consumer", &name, 2.0, &[]);
    let c = spawn_c(&c_exe, &name, 2.0);
    let mut victim = spawn_role("consumer", &name, 10.0, &[]);
    std::thread::sleep(Duration::from_millis(700));
    victim.kill().unwrap(); // SIGKILL, most likely in the middle of a copy
    let _ = victim.wait();
    assert_clean(&counters(survivor, "surviving rust consumer"), "rust", 50);
    assert_clean(&counters(c, "C consumer"), "C", 50);
    let p = counters(producer, "producer");
    assert!(p["published"] > 500, "{p:?}");
}

#[test]
fn restarted_producer_is_picked_up_by_waiting_consumers() {
    let name = ring_name("restart");
    let tmp = tempfile::tempdir().unwrap();
    let c_exe = build_c(tmp.path());
    let mut first = spawn_role("producer", &name, 30.0, &[]);
    let mut reader = RingReader::open_wait(&name, Duration::from_secs(10)).unwrap();
    let g1 = reader.generation();
    let c = spawn_c(&c_exe, &name, 4.0);
    let py = python().map(|py| spawn_py(py, &name, 4.0, None));
    // Let the consumers start (Python takes a while on a loaded machine) and attach.
    std::thread::sleep(Duration::from_millis(1500));
    first.kill().unwrap(); // crash: the segment stays, marked live, with a dead pid
    let _ = first.wait();
    assert!(matches!(
        reader.wait_next(Duration::from_millis(500)).unwrap(),
        Next::Frame(_) | Next::Timeout
    ));
    let second = spawn_role("producer", &name, 2.0, &[]);
    let started = Instant::now();
    let mut restarted = false;
    while started.elapsed() < Duration::from_secs(10) {
        match reader.wait_next(Duration::from_secs(1)).unwrap() {
            Next::Restarted { generation } => {
                assert_ne!(generation, g1);
                restarted = true;
            }
            Next::Frame(m) if restarted => {
                assert!(pattern_ok(m.frame, reader.pixels()));
                break;
            }
            _ => {}
        }
    }
    assert!(restarted, "the in-process reader never saw the restart");
    assert_eq!(reader.stats().restarts, 1);
    let k = counters(c, "C consumer");
    assert!(k["restarts"] >= 1, "C consumer missed the restart: {k:?}");
    assert_clean(&k, "C", 10);
    if let Some(py) = py {
        let k = counters(py, "Python consumer");
        assert!(
            k["restarts"] >= 1,
            "Python consumer missed the restart: {k:?}"
        );
        assert_eq!((k["bad"], k["nonincreasing"]), (0, 0), "{k:?}");
    }
    counters(second, "second producer");
    assert!(!Path::new("/dev/shm").join(&name).exists());
}
