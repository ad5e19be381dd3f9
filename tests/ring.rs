//! The shared-memory ring across processes: the C header matches the Rust layout, frames round
//! trip with their metadata, four consumers (Rust, C, Python) read a producer that publishes as
//! fast as it can without ever accepting a torn frame, a killed consumer harms nobody, a killed
//! and restarted producer is picked up; nobody else can squat, impersonate or take over a ring;
//! two producers started at once never both run; every reader survives hostile headers (fuzzed).
//!
//! Producers and Rust consumers run as child processes (`vkterrain-test-roles`,
//! tests/helpers/roles.rs), so every test is multi-process.

#[path = "helpers/mutate.rs"]
mod mutate;

use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use vkterrain::output::ring::layout::{self, FrameMeta, RingHeader, SlotHeader};
use vkterrain::output::ring::{
    Geometry, Next, ProducerOptions, RingLocation, RingProducer, RingReader,
};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn euid() -> u32 {
    // SAFETY: no arguments, cannot fail.
    unsafe { libc::geteuid() }
}

/// A ring directory of this test run on tmpfs (`/dev/shm/vkt-test-<tag>-<pid>`, mode 0700),
/// removed with everything in it on drop. `/dev/shm` is sticky and world-writable, so readers
/// name the owner explicitly ([`euid`]).
struct TestDir(PathBuf);

impl TestDir {
    fn new(tag: &str) -> Self {
        let p = PathBuf::from(format!("/dev/shm/vkt-test-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir(&p).unwrap();
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o700)).unwrap();
        TestDir(p)
    }
    fn loc(&self, name: &str) -> RingLocation {
        RingLocation::new(&self.0, name).unwrap()
    }
    fn path(&self) -> &Path {
        &self.0
    }
    fn s(&self) -> String {
        self.0.display().to_string()
    }
}

impl Drop for TestDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// CI runs as root; the tests that need a second user only skip (loudly) outside CI.
fn require_root(test: &str) -> bool {
    if euid() == 0 {
        return true;
    }
    assert!(
        std::env::var("CI").is_err(),
        "{test} needs root (CI runs as root) to act as a second user"
    );
    eprintln!("SKIPPING {test}: needs root to act as a second user");
    false
}

/// The test pattern (the same as the roles helper's): frame number in bytes 0..8, CRC-32 of
/// bytes 16.. in bytes 8..12, the rest pseudo-random per frame.
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

fn roles() -> Command {
    Command::new(env!("CARGO_BIN_EXE_vkterrain-test-roles"))
}

fn spawn_role(role: &str, dir: &TestDir, name: &str, seconds: f64, extra: &[&str]) -> Child {
    let mut c = roles();
    c.arg(role)
        .arg(format!("dir={}", dir.s()))
        .arg(format!("name={name}"))
        .arg(format!("seconds={seconds}"))
        .arg(format!("owner={}", euid()))
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
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

/// python3 (never silently missing in CI).
fn python() -> Option<&'static str> {
    let ok = Command::new("python3")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        assert!(std::env::var("CI").is_err(), "python3 is missing in CI");
        eprintln!("SKIPPING the Python consumer: python3 is not installed");
    }
    ok.then_some("python3")
}

fn spawn_c(exe: &Path, dir: &TestDir, name: &str, seconds: f64, ready: Option<&Path>) -> Child {
    let mut c = Command::new(exe);
    c.args([name, "--verify", "--seconds", &seconds.to_string()])
        .args(["--dir", &dir.s(), "--owner", &euid().to_string()]);
    if let Some(r) = ready {
        c.arg("--ready").arg(r);
    }
    c.stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn spawn_py(
    py: &str,
    dir: &TestDir,
    name: &str,
    seconds: f64,
    save: Option<&Path>,
    ready: Option<&Path>,
) -> Child {
    let mut c = Command::new(py);
    c.arg(root().join("consumers/python/vkterrain_ring.py"))
        .args([name, "--verify", "--seconds", &seconds.to_string()])
        .args(["--dir", &dir.s(), "--owner", &euid().to_string()]);
    if let Some(s) = save {
        c.arg("--save").arg(s);
    }
    if let Some(r) = ready {
        c.arg("--ready").arg(r);
    }
    c.stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Waits until consumer `child` has created its `--ready` file (it has read a frame); fails
/// with the child's output if it exits first or takes longer than `limit`.
fn wait_ready(child: &mut Child, ready: &Path, who: &str, limit: Duration) {
    let started = Instant::now();
    while !ready.exists() {
        if let Some(status) = child.try_wait().unwrap() {
            let mut out = String::new();
            if let Some(mut o) = child.stdout.take() {
                let _ = o.read_to_string(&mut out);
            }
            if let Some(mut e) = child.stderr.take() {
                let _ = e.read_to_string(&mut out);
            }
            panic!("{who} exited ({status}) before reading a frame: {out}");
        }
        assert!(
            started.elapsed() < limit,
            "{who} read no frame within {limit:?}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A producer role that publishes until the test has what it needs (at most 60 s): slow
/// consumers (Python on a loaded machine) never find the ring gone. [`StoppableProducer::stop`]
/// ends it and returns its counters.
struct StoppableProducer {
    child: Child,
    stop: PathBuf,
}

impl StoppableProducer {
    fn spawn(dir: &TestDir, name: &str, extra: &[&str]) -> Self {
        let stop = PathBuf::from(dir.s()).join(format!("{name}.stop"));
        let arg = format!("stop={}", stop.display());
        let mut args = vec![arg.as_str()];
        args.extend_from_slice(extra);
        let child = spawn_role("producer", dir, name, 60.0, &args);
        StoppableProducer { child, stop }
    }

    fn stop(self) -> BTreeMap<String, u64> {
        std::fs::write(&self.stop, b"").unwrap();
        counters(self.child, "producer")
    }
}

/// Waits for a child and parses its `key=value` counter line.
fn counters(child: Child, who: &str) -> BTreeMap<String, u64> {
    let o = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{who} failed: {stdout}\n{stderr}");
    let line = stdout
        .lines()
        .find_map(|l| {
            l.find("received=")
                .or_else(|| l.find("published="))
                .or_else(|| l.find("cases="))
                .map(|i| &l[i..])
        })
        .unwrap_or_else(|| panic!("{who} printed no counters: {stdout}\n{stderr}"));
    line.split_whitespace()
        .filter_map(|kv| kv.split_once('='))
        .filter_map(|(k, v)| Some((k.to_string(), v.parse().ok()?)))
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
    let want = rust_layout();
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
    if let Some(py) = python() {
        python_offsets_match_rust_layout(py);
    }
}

/// Sizes and field offsets of the ring's shared structs as Rust lays them out, named as the C
/// reader's `--layout` prints them (`struct.field`, `struct.size`).
fn rust_layout() -> BTreeMap<String, usize> {
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
    off!("vkt_ring_header", RingHeader, flags);
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
        ("height_datum", offset_of!(FrameMeta, height_datum)),
        ("lat_deg", offset_of!(FrameMeta, lat_deg)),
        ("lon_deg", offset_of!(FrameMeta, lon_deg)),
        ("height_m", offset_of!(FrameMeta, height_m)),
        ("heading_deg", offset_of!(FrameMeta, heading_deg)),
        ("local_pitch_deg", offset_of!(FrameMeta, local_pitch_deg)),
        ("local_roll_deg", offset_of!(FrameMeta, local_roll_deg)),
        ("_reserved2", offset_of!(FrameMeta, _reserved2)),
    ] {
        want.insert(format!("vkt_frame_meta.{c}"), r);
    }
    want
}

/// The Python module's offsets and metadata format equal Rust's.
fn python_offsets_match_rust_layout(py: &str) {
    use std::mem::{offset_of, size_of};
    let script = format!(
        "import sys; sys.path.insert(0, {:?}); import vkterrain_ring as v; \
         print(v.HEADER_SIZE, v.H_GENERATION, v.H_SLOT_SIZE, v.H_PIXELS_OFFSET, v.H_PID, \
         v.H_LATEST, v.H_STATE, v.H_FLAGS, v.H_WAKE, v.H_PUBLISHED, v.S_META, v.META_SIZE, v.MAGIC, \
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
        offset_of!(RingHeader, flags) as u64,
        offset_of!(RingHeader, wake) as u64,
        offset_of!(RingHeader, published) as u64,
        offset_of!(SlotHeader, meta) as u64,
        size_of::<FrameMeta>() as u64,
        layout::MAGIC,
        offset_of!(FrameMeta, _reserved2) as u64,
    ];
    assert_eq!(got, want, "Python offsets differ from the Rust layout");
}

#[test]
fn round_trip_metadata_timeout_view_close_and_permissions() {
    let dir = TestDir::new("rt");
    let loc = dir.loc("rt");
    let g = Geometry::new(8, 4, 3, true);
    let mut p = RingProducer::create(&loc, g, &ProducerOptions::default()).unwrap();
    let path = loc.segment_path();
    let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o600, "segment mode");
    // Slots and pixels are page aligned (what zero-copy imports need).
    let l = p.layout();
    assert_eq!(
        (
            l.header_size % 4096,
            l.slot_size % 4096,
            l.pixels_offset % 4096
        ),
        (0, 0, 0)
    );

    let mut r = RingReader::open(&loc, Some(euid())).unwrap();
    assert_eq!(r.geometry(), g);
    assert_eq!(r.layout(), l);
    assert_eq!(r.generation(), p.generation());
    assert!(r.producer_alive(), "the producer holds its segment");
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
    drop(p);
    assert!(!loc.lock_path().exists(), "name lock left behind");
    assert!(RingReader::open(&loc, Some(euid())).is_err());
}

#[test]
fn names_stale_segments_and_live_producers_are_checked() {
    let dir = TestDir::new("names");
    let g = Geometry::new(4, 4, 2, false);
    for bad in ["", "a/b", "..", ".hidden", "sp ace", &"x".repeat(201), "ü"] {
        let e = RingLocation::new(dir.path(), bad)
            .err()
            .unwrap_or_else(|| panic!("{bad:?} accepted"));
        assert!(e.to_string().contains("ring name"), "{e}");
    }
    for (w, slots) in [(0, 2), (4, 1), (4, 65), (20000, 2)] {
        let g = Geometry::new(w, 4, slots, false);
        assert!(RingProducer::create(&dir.loc("geom"), g, &ProducerOptions::default()).is_err());
    }
    // A live producer (another process holding the name) is never replaced.
    let live = spawn_role("producer", &dir, "live", 3.0, &[]);
    let start = Instant::now();
    while !dir.loc("live").segment_path().exists() {
        assert!(start.elapsed() < Duration::from_secs(10));
        std::thread::sleep(Duration::from_millis(10));
    }
    let e = RingProducer::create(&dir.loc("live"), g, &ProducerOptions::default())
        .err()
        .expect("replaced a live producer");
    assert!(e.to_string().contains("in use by a live process"), "{e}");
    counters(live, "producer");

    // A crashed producer's segment whose header names a live foreign pid (1) is stale all the
    // same: the name's lock, not a pid, says who is alive. It is replaced, not refused.
    let loc = dir.loc("stale");
    let mut crashed = spawn_role("producer", &dir, "stale", 30.0, &[]);
    let mut r = RingReader::open_wait(&loc, Some(euid()), Duration::from_secs(10)).unwrap();
    crashed.kill().unwrap();
    let _ = crashed.wait();
    {
        use std::os::unix::fs::FileExt;
        let f = std::fs::OpenOptions::new()
            .write(true)
            .open(loc.segment_path())
            .unwrap();
        f.write_all_at(&1u32.to_le_bytes(), 60).unwrap();
    }
    let p = RingProducer::create(&loc, g, &ProducerOptions::default())
        .expect("a stale segment naming a live pid blocked the producer");
    let start = Instant::now();
    while !matches!(
        r.wait_next(Duration::from_secs(1)).unwrap(),
        Next::Restarted { .. }
    ) {
        assert!(start.elapsed() < Duration::from_secs(10), "no restart seen");
    }
    drop(p);

    // Not-a-ring files are rejected by readers with one line, and replaced by producers.
    let junk = dir.loc("junk");
    std::fs::File::create(junk.segment_path())
        .unwrap()
        .write_all(&[7u8; 512])
        .unwrap();
    let e = RingReader::open(&junk, Some(euid()))
        .err()
        .expect("junk accepted");
    assert!(
        e.to_string().contains("magic") && !e.to_string().contains('\n'),
        "{e}"
    );
    let p = RingProducer::create(&junk, g, &ProducerOptions::default()).unwrap();
    assert!(RingReader::open(&junk, Some(euid())).is_ok());
    drop(p);
    assert!(!junk.segment_path().exists());
}

#[test]
fn producer_liveness_is_the_lock_not_the_pid() {
    // A crashed producer (SIGKILL) leaves its segment "live" in the state word; readers and
    // `status` see that no process holds it.
    let dir = TestDir::new("alive");
    let mut first = spawn_role("producer", &dir, "alive", 30.0, &[]);
    let r =
        RingReader::open_wait(&dir.loc("alive"), Some(euid()), Duration::from_secs(10)).unwrap();
    assert!(r.producer_alive());
    first.kill().unwrap();
    let _ = first.wait();
    assert_eq!(
        r.state(),
        layout::STATE_LIVE,
        "the state word still says live"
    );
    assert!(!r.producer_alive(), "a dead producer reported alive");
}

#[test]
fn simultaneous_producers_exactly_one_runs() {
    let dir = TestDir::new("race");
    for trial in 0..6 {
        let name = format!("race{trial}");
        let at = vkterrain::output::ring::sys::realtime_ns() + 400_000_000;
        let kids: Vec<Child> = (0..3)
            .map(|_| {
                roles()
                    .args(["race", &format!("dir={}", dir.s()), &format!("name={name}")])
                    .arg(format!("at_ns={at}"))
                    .arg("hold_ms=600")
                    .stdout(Stdio::piped())
                    .stderr(Stdio::piped())
                    .spawn()
                    .unwrap()
            })
            .collect();
        let mut created = 0;
        for k in kids {
            let o = k.wait_with_output().unwrap();
            let out = String::from_utf8_lossy(&o.stdout);
            assert!(
                o.status.success(),
                "{out} {}",
                String::from_utf8_lossy(&o.stderr)
            );
            if out.contains("created=1") {
                created += 1;
            } else {
                assert!(out.contains("in_use_by_a_live_process"), "{out}");
            }
        }
        assert_eq!(
            created, 1,
            "trial {trial}: {created} producers ran on one ring"
        );
    }
}

/// Runs `f` as uid/gid 65534 (nobody) in a child process: `sh -c SCRIPT`.
fn as_nobody(script: &str) -> std::process::Output {
    use std::os::unix::process::CommandExt;
    Command::new("/bin/sh")
        .args(["-c", script])
        .uid(65534)
        .gid(65534)
        .output()
        .unwrap()
}

#[test]
fn other_users_can_neither_squat_nor_impersonate() {
    if !require_root("other_users_can_neither_squat_nor_impersonate") {
        return;
    }
    let dir = TestDir::new("squat");
    let loc = dir.loc("victim");
    // 1. The world-writable namespace: another user's fake segment under the same name in
    //    /dev/shm (the old attack) neither blocks nor impersonates the producer.
    let fake = PathBuf::from(format!("/dev/shm/victim-{}", std::process::id()));
    let o = as_nobody(&format!(
        "printf 'VKTRING1\\002\\000\\000\\000' > {0} && chmod 644 {0}",
        fake.display()
    ));
    assert!(o.status.success(), "{o:?}");
    assert_eq!(
        std::os::unix::fs::MetadataExt::uid(&std::fs::metadata(&fake).unwrap()),
        65534
    );
    let p = RingProducer::create(
        &loc,
        Geometry::new(8, 8, 2, false),
        &ProducerOptions::default(),
    )
    .expect("another user's file blocked the producer");
    // 2. Nobody else can create anything in the ring directory (mode 0700, ours).
    for target in [
        loc.segment_path(),
        loc.lock_path(),
        dir.path().join("other"),
    ] {
        let o = as_nobody(&format!("echo x > {}", target.display()));
        assert!(!o.status.success(), "nobody wrote {}", target.display());
    }
    // 3. A directory someone else made first is refused, naming the problem (never used).
    let squatted = PathBuf::from(format!("/dev/shm/vkt-squatted-{}", std::process::id()));
    let o = as_nobody(&format!("mkdir -m 777 {}", squatted.display()));
    assert!(o.status.success(), "{o:?}");
    let e = RingProducer::create(
        &RingLocation::new(&squatted, "x").unwrap(),
        Geometry::new(8, 8, 2, false),
        &ProducerOptions::default(),
    )
    .err()
    .expect("a squatted directory was used");
    assert!(e.to_string().contains("uid 65534"), "{e}");
    let _ = std::fs::remove_dir_all(&squatted);
    let _ = std::fs::remove_file(&fake);
    drop(p);
}

/// A producer of one published 8x8 frame at `loc` (the frame: `pattern(0)`).
fn one_frame_ring(loc: &RingLocation) -> RingProducer {
    let g = Geometry::new(8, 8, 2, false);
    let mut p = RingProducer::create(loc, g, &ProducerOptions::default()).unwrap();
    let mut px = vec![0u8; 256];
    pattern(0, &mut px);
    p.publish(&test_meta(g), &px, None).unwrap();
    p
}

/// Whether the Rust, C (`c_exe`) and Python readers, each expecting owner uid 0, accept ring
/// `copy` of `dir`; the Python one counts as accepting where no Python is installed.
fn readers_accept(dir: &TestDir, c_exe: &Path) -> [bool; 3] {
    let rust = RingReader::open(&dir.loc("copy"), Some(0)).is_ok();
    let d = dir.s();
    let common = ["copy", "--dir", &d, "--owner", "0", "--frames", "1"];
    let received = |o: std::process::Output| {
        o.status.success() && String::from_utf8_lossy(&o.stdout).contains("received=1")
    };
    let c_ok = received(
        Command::new(c_exe)
            .args(common)
            .args(["--timeout-ms", "2000"])
            .output()
            .unwrap(),
    );
    let py_ok = python().is_none_or(|py| {
        let script = root().join("consumers/python/vkterrain_ring.py");
        let mut c = Command::new(py);
        c.arg(script).args(common).args(["--timeout", "2"]);
        received(c.output().unwrap())
    });
    [rust, c_ok, py_ok]
}

/// Readers: a copy of a genuine ring is accepted when it belongs to the expected owner and
/// nobody else may write it (positive control), refused when it belongs to someone else or is
/// writable by others; by Rust, C and Python alike.
#[test]
fn readers_refuse_rings_others_own_or_may_write() {
    if !require_root("readers_refuse_rings_others_own_or_may_write") {
        return;
    }
    let dir = TestDir::new("impersonate");
    let tmp = tempfile::tempdir().unwrap();
    let c_exe = build_c(tmp.path());
    let src = TestDir::new("impersonate-src");
    let p = one_frame_ring(&src.loc("genuine"));
    let copy = dir.path().join("copy");
    let case = |uid: u32, mode: u32| -> [bool; 3] {
        std::fs::copy(src.loc("genuine").segment_path(), &copy).unwrap();
        std::os::unix::fs::chown(&copy, Some(uid), None).unwrap();
        std::fs::set_permissions(&copy, std::fs::Permissions::from_mode(mode)).unwrap();
        readers_accept(&dir, &c_exe)
    };
    assert_eq!(case(0, 0o600), [true; 3], "a genuine ring was refused");
    assert_eq!(
        case(0, 0o640),
        [true; 3],
        "a group-readable genuine ring was refused"
    );
    let refused = |r: [bool; 3]| r.iter().all(|ok| !ok) || (python().is_none() && !r[0] && !r[1]);
    assert!(
        refused(case(65534, 0o600)),
        "a ring of another user was accepted"
    );
    assert!(
        refused(case(0, 0o666)),
        "a ring writable by others was accepted"
    );
    assert!(
        refused(case(0, 0o620)),
        "a ring writable by the group was accepted"
    );
    drop(p);
}

/// Without a named owner, a reader trusts the directory's owner only where nobody else can
/// write: in a sticky world-writable tree (/dev/shm) it asks for the owner; under the build's
/// own temporary directory (when no ancestor is group- or world-writable) it opens.
#[test]
fn readers_without_an_owner_trust_only_directories_nobody_else_writes() {
    let dir = TestDir::new("no-owner");
    let p = one_frame_ring(&dir.loc("shm"));
    let e = RingReader::open(&dir.loc("shm"), None)
        .err()
        .expect("owner inferred in /dev/shm");
    assert!(e.to_string().contains("name the expected owner"), "{e}");
    drop(p);
    let safe =
        PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("rings-{}", std::process::id()));
    let safe_loc = RingLocation::new(&safe, "safe").unwrap();
    let sp = one_frame_ring(&safe_loc);
    let root_chain = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .ancestors()
        .all(|a| std::fs::metadata(a).is_ok_and(|m| m.permissions().mode() & 0o022 == 0));
    if root_chain {
        assert!(RingReader::open(&safe_loc, None).is_ok());
    }
    drop(sp);
    let _ = std::fs::remove_dir_all(&safe);
}

#[test]
fn stress_four_consumers_rust_c_python() {
    let dir = TestDir::new("stress");
    let tmp = tempfile::tempdir().unwrap();
    let c_exe = build_c(tmp.path());
    let secs = 3.0;
    let producer = StoppableProducer::spawn(&dir, "stress", &[]);
    std::thread::sleep(Duration::from_millis(300));
    let r1 = spawn_role("consumer", &dir, "stress", secs, &[]);
    let r2 = spawn_role("consumer", &dir, "stress", secs, &[]);
    let c = spawn_c(&c_exe, &dir, "stress", secs, None);
    let png = tmp.path().join("py.png");
    let py = python().map(|py| spawn_py(py, &dir, "stress", secs, Some(&png), None));
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
    let p = producer.stop();
    eprintln!("producer: {p:?}");
    assert!(p["published"] > 500, "producer too slow: {p:?}");
}

#[test]
fn verifiers_detect_corrupt_frames() {
    // The checksum check the stress test relies on must be able to fail.
    let dir = TestDir::new("corrupt");
    let tmp = tempfile::tempdir().unwrap();
    let c_exe = build_c(tmp.path());
    let producer = StoppableProducer::spawn(&dir, "corrupt", &["corrupt=1"]);
    std::thread::sleep(Duration::from_millis(200));
    let r = spawn_role("consumer", &dir, "corrupt", 1.0, &[]);
    let c = spawn_c(&c_exe, &dir, "corrupt", 1.0, None);
    let py = python().map(|py| spawn_py(py, &dir, "corrupt", 1.0, None, None));
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
    producer.stop();
}

#[test]
fn killed_consumer_does_not_affect_producer_or_others() {
    let dir = TestDir::new("kill");
    let tmp = tempfile::tempdir().unwrap();
    let c_exe = build_c(tmp.path());
    let producer = StoppableProducer::spawn(&dir, "kill", &[]);
    std::thread::sleep(Duration::from_millis(300));
    let survivor = spawn_role("consumer", &dir, "kill", 2.0, &[]);
    let c = spawn_c(&c_exe, &dir, "kill", 2.0, None);
    let mut victim = spawn_role("consumer", &dir, "kill", 10.0, &[]);
    std::thread::sleep(Duration::from_millis(700));
    victim.kill().unwrap(); // SIGKILL, most likely in the middle of a copy
    let _ = victim.wait();
    assert_clean(&counters(survivor, "surviving rust consumer"), "rust", 50);
    assert_clean(&counters(c, "C consumer"), "C", 50);
    let p = producer.stop();
    assert!(p["published"] > 500, "{p:?}");
}

#[test]
fn restarted_producer_is_picked_up_by_waiting_consumers() {
    let dir = TestDir::new("restart");
    let loc = dir.loc("restart");
    let tmp = tempfile::tempdir().unwrap();
    let c_exe = build_c(tmp.path());
    let mut first = spawn_role("producer", &dir, "restart", 30.0, &[]);
    let mut reader = RingReader::open_wait(&loc, Some(euid()), Duration::from_secs(10)).unwrap();
    let g1 = reader.generation();
    // The consumers run until the second producer closes the ring (or 60 s pass).
    let c_ready = tmp.path().join("c.ready");
    let py_ready = tmp.path().join("py.ready");
    let mut c = spawn_c(&c_exe, &dir, "restart", 60.0, Some(&c_ready));
    let mut py = python().map(|py| spawn_py(py, &dir, "restart", 60.0, None, Some(&py_ready)));
    // The crash must come after every consumer read a frame of the first producer (Python
    // takes seconds to start on a loaded machine): else it would open the second producer's
    // ring directly and never see a restart.
    wait_ready(&mut c, &c_ready, "C consumer", Duration::from_secs(30));
    if let Some(py) = &mut py {
        wait_ready(py, &py_ready, "Python consumer", Duration::from_secs(30));
    }
    first.kill().unwrap(); // crash: the segment stays, marked live, its lock gone
    let _ = first.wait();
    assert!(matches!(
        reader.wait_next(Duration::from_millis(500)).unwrap(),
        Next::Frame(_) | Next::Timeout
    ));
    let second = spawn_role("producer", &dir, "restart", 3.0, &[]);
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
    assert!(!loc.segment_path().exists());
}

/// A valid segment with three frames (the fuzzers' template): 8x4 pixels, 2 slots, depth.
fn fuzz_template(dir: &TestDir) -> Vec<u8> {
    let loc = dir.loc("template");
    let g = Geometry::new(8, 4, 2, true);
    let mut p = RingProducer::create(&loc, g, &ProducerOptions::default()).unwrap();
    let mut px = vec![0u8; g.pixel_bytes() as usize];
    let depth = vec![0.5f32; 32];
    for f in 0..3 {
        pattern(f, &mut px);
        p.publish(&test_meta(g), &px, Some(&depth)).unwrap();
    }
    let bytes = std::fs::read(loc.segment_path()).unwrap();
    drop(p);
    bytes
}

/// Opens a (possibly hostile) segment and reads whatever it offers; every frame returned must
/// agree with the checked header. Returns (opened, frames).
fn read_hostile(loc: &RingLocation) -> (bool, u64) {
    let Ok(mut r) = RingReader::open(loc, Some(euid())) else {
        return (false, 0);
    };
    let g = r.geometry();
    let mut frames = 0;
    for _ in 0..3 {
        match r.wait_next(Duration::ZERO) {
            Ok(Next::Frame(m)) => {
                assert_eq!(
                    (m.width, m.height, m.row_stride),
                    (g.width, g.height, g.width * 4)
                );
                assert_eq!(r.pixels().len() as u64, g.pixel_bytes());
                frames += 1;
            }
            Ok(_) | Err(_) => break,
        }
    }
    if let Some(v) = r.view() {
        assert_eq!(v.pixels().len() as u64, g.pixel_bytes());
        let _ = v.pixels().iter().map(|&b| b as u64).sum::<u64>();
    }
    (true, frames)
}

#[test]
fn rust_reader_survives_hostile_headers() {
    use proptest::prelude::*;
    let dir = TestDir::new("fuzz-rs");
    let template = fuzz_template(&dir);
    // Positive control: the unmutated template opens and yields a frame.
    std::fs::write(dir.path().join("case"), &template).unwrap();
    assert_eq!(read_hostile(&dir.loc("case")), (true, 1));
    let case_path = dir.path().join("case");
    let loc = dir.loc("case");
    let opened = std::cell::Cell::new(0u64);
    let mut runner = proptest::test_runner::TestRunner::new(ProptestConfig::with_cases(3000));
    runner
        .run(&any::<u64>(), |seed| {
            let bytes = mutate::mutate(&template, &mut mutate::Rng(seed | 1));
            std::fs::write(&case_path, &bytes).unwrap();
            opened.set(opened.get() + read_hostile(&loc).0 as u64);
            Ok(())
        })
        .unwrap();
    // The mutations must leave some segments openable, or the slot checks go untested.
    eprintln!("Rust fuzz: 3000 cases, {} opened", opened.get());
    assert!(opened.get() > 0, "no mutated segment opened");
}

#[test]
fn c_and_python_readers_survive_hostile_headers() {
    let dir = TestDir::new("fuzz-c");
    let template = dir.path().join("template.bin");
    std::fs::write(&template, fuzz_template(&dir)).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    // The C fuzzer under AddressSanitizer: any out-of-bounds read aborts it.
    let exe = tmp.path().join("ring_fuzz");
    let o = Command::new("cc")
        .args(["-O1", "-g", "-std=c11", "-Wall", "-Wextra", "-Werror"])
        .args(["-fsanitize=address,undefined", "-fno-sanitize-recover=all"])
        .arg("-I")
        .arg(root().join("consumers/c"))
        .arg("-o")
        .arg(&exe)
        .arg(root().join("tests/helpers/ring_fuzz.c"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let run = |naive: bool| {
        let mut c = Command::new(&exe);
        c.arg(&template).arg(dir.path()).args(["4000", "7"]);
        if naive {
            c.arg("--naive");
        }
        c.output().unwrap()
    };
    let o = run(false);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "C reader crashed: {out}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let k: BTreeMap<String, u64> = out
        .split_whitespace()
        .filter_map(|kv| kv.split_once('='))
        .filter_map(|(k, v)| Some((k.to_string(), v.parse().ok()?)))
        .collect();
    eprintln!("C fuzz (ASan): {out}");
    assert_eq!(k["cases"], 4000, "{out}");
    assert!(
        k["opened"] > 0 && k["frames"] > 0 && k["rejected"] > 0,
        "{out}"
    );
    assert_eq!(k["violations"], 0, "{out}");
    // Negative control: a reader that trusts the header (as the old one did) is caught.
    let o = run(true);
    eprintln!("C fuzz, trusting reader: {:?}", o.status);
    assert!(
        !o.status.success(),
        "the fuzzer cannot catch a trusting reader"
    );

    if let Some(py) = python() {
        let script = root().join("tests/helpers/ring_fuzz.py");
        let run = |naive: bool| {
            let mut c = Command::new(py);
            c.arg(&script)
                .arg(&template)
                .arg(dir.path())
                .args(["3000", "11"])
                .env("PYTHONPATH", root().join("consumers/python"));
            if naive {
                c.arg("--naive");
            }
            c.output().unwrap()
        };
        let o = run(false);
        let out = String::from_utf8_lossy(&o.stdout);
        eprintln!("Python fuzz: {out}");
        assert!(
            o.status.success(),
            "Python reader failed: {out}\n{}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(
            out.contains("cases=3000") && out.contains("violations=0"),
            "{out}"
        );
        assert!(
            !out.contains("opened=0 ") && !out.contains("frames=0 "),
            "{out}"
        );
        let o = run(true);
        let out = String::from_utf8_lossy(&o.stdout);
        eprintln!("Python fuzz, trusting reader: exit {:?} {out}", o.status);
        assert!(
            !o.status.success() || !out.contains("violations=0"),
            "the fuzzer cannot catch a trusting Python reader: {out}"
        );
    }
}
