//! `vkterrain-test-roles`: the child processes of `tests/ring.rs` and `tests/serve.rs` (a test
//! helper, built for the integration tests; not part of the product). Every role prints one
//! `key=value` line the tests parse. Usage: `vkterrain-test-roles ROLE [KEY=VALUE...]`.
//!
//! Roles: `producer dir= name= seconds= [side=64] [corrupt=1] [stop=FILE]` (publishes the test
//! pattern as fast as it can, for `seconds` or until FILE exists), `consumer dir= name= seconds= [owner=]` (verifies every frame),
//! `race dir= name= at_ns= hold_ms=` (creates a ring at a `CLOCK_REALTIME` instant, reports
//! whether it got it), `register sock= count= [prefix=]` (reports `count` consumers over the
//! control socket, then waits for its stdin to close), `efbig path=` (writes a file past
//! `RLIMIT_FSIZE` with `output::write_atomic`).

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use vkterrain::output::ring::{
    FrameMeta, Geometry, Next, ProducerOptions, RingLocation, RingProducer, RingReader,
};

fn crc32(data: &[u8]) -> u32 {
    let mut table = [0u32; 256];
    for (i, t) in table.iter_mut().enumerate() {
        let mut c = i as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
        *t = c;
    }
    let mut c = 0xFFFF_FFFFu32;
    for &b in data {
        c = table[((c ^ b as u32) & 0xFF) as usize] ^ (c >> 8);
    }
    c ^ 0xFFFF_FFFF
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
    let crc = crc32(&buf[16..]);
    buf[..8].copy_from_slice(&frame.to_le_bytes());
    buf[8..12].copy_from_slice(&crc.to_le_bytes());
    buf[12..16].fill(0);
}

fn pattern_ok(frame: u64, buf: &[u8]) -> bool {
    buf.len() >= 16
        && buf[..8] == frame.to_le_bytes()
        && buf[8..12] == crc32(&buf[16..]).to_le_bytes()
}

fn location(a: &BTreeMap<String, String>) -> RingLocation {
    RingLocation::new(&a["dir"], &a["name"]).unwrap()
}

fn producer(a: &BTreeMap<String, String>) {
    let end = Instant::now() + Duration::from_secs_f64(a["seconds"].parse().unwrap());
    let side: u32 = a.get("side").map_or(64, |s| s.parse().unwrap());
    let g = Geometry::new(side, side, 4, false);
    let corrupt = a.contains_key("corrupt");
    let mut p = RingProducer::create(&location(a), g, &ProducerOptions::default()).unwrap();
    let mut buf = vec![0u8; g.pixel_bytes() as usize];
    let meta = FrameMeta {
        width: side,
        height: side,
        vfov_deg: 60.0,
        ..Default::default()
    };
    let stop = a.get("stop").map(std::path::PathBuf::from);
    let mut checked = Instant::now();
    while Instant::now() < end {
        if let Some(stop) = &stop
            && checked.elapsed() > Duration::from_millis(10)
        {
            if stop.exists() {
                break;
            }
            checked = Instant::now();
        }
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

fn consumer(a: &BTreeMap<String, String>) {
    let end = Instant::now() + Duration::from_secs_f64(a["seconds"].parse().unwrap());
    let owner = a.get("owner").map(|o| o.parse().unwrap());
    let mut r = RingReader::open_wait(&location(a), owner, Duration::from_secs(5)).unwrap();
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
        "received={} lost={} gaps={gaps} bad={bad} nonincreasing={nonincreasing} torn_retries={} restarts={} bad_slots={} closed={closed}",
        s.received, s.lost, s.torn_retries, s.restarts, s.bad_slots
    );
}

/// Creates the ring at the instant `at_ns` (so that several processes try at once), keeps it
/// `hold_ms`, prints `created=1` or `created=0` and the reason.
fn race(a: &BTreeMap<String, String>) {
    let at: u64 = a["at_ns"].parse().unwrap();
    while vkterrain::output::ring::sys::realtime_ns() < at {
        std::hint::spin_loop();
    }
    match RingProducer::create(
        &location(a),
        Geometry::new(8, 8, 2, false),
        &ProducerOptions::default(),
    ) {
        Ok(p) => {
            std::thread::sleep(Duration::from_millis(a["hold_ms"].parse().unwrap()));
            println!("created=1 published={}", p.published());
        }
        Err(e) => println!("created=0 reason={}", e.to_string().replace(' ', "_")),
    }
}

fn register(a: &BTreeMap<String, String>) {
    let sock = std::os::unix::net::UnixDatagram::unbound().unwrap();
    let count: usize = a["count"].parse().unwrap();
    let prefix = a.get("prefix").map_or("fake", String::as_str);
    for i in 0..count {
        let msg = format!(r#"{{"consumer":{{"name":"{prefix}-{i}","received":1,"lost":0}}}}"#);
        sock.send_to(msg.as_bytes(), &a["sock"]).unwrap();
    }
    println!("sent={count}");
    // Stay alive (a live consumer) until the test closes our stdin.
    let mut sink = String::new();
    let _ = std::io::stdin().read_line(&mut sink);
}

fn efbig(a: &BTreeMap<String, String>) {
    // SAFETY: plain libc calls on this single-threaded process.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
        let lim = libc::rlimit {
            rlim_cur: 16,
            rlim_max: 16,
        };
        libc::setrlimit(libc::RLIMIT_FSIZE, &lim);
    }
    let r = vkterrain::output::write_atomic(std::path::Path::new(&a["path"]), &[b'x'; 4096]);
    println!("failed={}", r.is_err() as u8);
}

fn main() {
    let mut args = std::env::args().skip(1);
    let role = args
        .next()
        .expect("usage: vkterrain-test-roles ROLE [KEY=VALUE...]");
    let a: BTreeMap<String, String> = args
        .filter_map(|kv| {
            kv.split_once('=')
                .map(|(k, v)| (k.to_string(), v.to_string()))
        })
        .collect();
    match role.as_str() {
        "producer" => producer(&a),
        "consumer" => consumer(&a),
        "race" => race(&a),
        "register" => register(&a),
        "efbig" => efbig(&a),
        other => panic!("unknown role {other}"),
    }
}
