//! `vkterrain subscribe`: the Rust Zenoh subscriber of `serve`'s frames (`docs/zenoh.md`).
//! Prints one line per frame (`frame=.. x=.. latency_us=..`) and a summary line; `--save`
//! writes the last frame as PNG; `--control JSON` sends one control message instead;
//! `--status` prints the service's status (its queryable).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Args;
use zenoh::Wait;

use crate::output::ring::sys::monotonic_ns;
use crate::render::stats::Percentiles;
use crate::service::ZenohSettings;
use crate::service::zenoh::{Keys, Payload, open_session, parse_payload};

#[derive(Args, Debug, Clone, Default)]
pub struct SubscribeArgs {
    /// Ring name of the service (the key expressions are `<prefix>/<ring>/...`).
    #[arg(long, default_value = "vkterrain")]
    pub ring: String,
    /// Key prefix (`zenoh.prefix` of the service).
    #[arg(long, default_value = "vkterrain")]
    pub prefix: String,
    /// Endpoint to connect to (repeatable), e.g. tcp/127.0.0.1:7447.
    #[arg(long)]
    pub connect: Vec<String>,
    /// Endpoint to listen on (repeatable).
    #[arg(long)]
    pub listen: Vec<String>,
    /// Stop after this many frames (default: until --seconds).
    #[arg(long)]
    pub frames: Option<u64>,
    /// Stop after this long.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Write the last frame received as PNG.
    #[arg(long)]
    pub save: Option<PathBuf>,
    /// Send this control message (JSON) to the service and exit.
    #[arg(long)]
    pub control: Option<String>,
    /// Print the service's status (JSON) and exit.
    #[arg(long)]
    pub status: bool,
    /// Turn Zenoh shared memory off on this side (frames then come over the network).
    #[arg(long)]
    pub no_shm: bool,
    /// Print only the summary line, not a line per frame.
    #[arg(long)]
    pub quiet: bool,
}

pub fn run(args: &SubscribeArgs) -> anyhow::Result<()> {
    crate::output::ring::validate_name(&args.ring)?;
    let settings = ZenohSettings {
        enabled: true,
        prefix: args.prefix.clone(),
        connect: args.connect.clone(),
        listen: args.listen.clone(),
        shared_memory: !args.no_shm,
        ..Default::default()
    };
    settings.validate()?;
    let session = open_session(&settings)?;
    let keys = Keys::of(&settings.prefix, &args.ring);
    let deadline = Instant::now() + Duration::from_secs_f64(args.seconds.max(0.0));
    if let Some(msg) = &args.control {
        return send_control(&session, &keys, msg);
    }
    if args.status {
        return print_status(&session, &keys, deadline, args.seconds);
    }
    receive_frames(args, &session, &keys, deadline)?;
    let _ = session.close().wait();
    Ok(())
}

/// A bounded handler that drops the oldest sample when full (a slow subscriber skips frames,
/// counted in `lost`, and never holds the publisher up).
fn newest_frames() -> zenoh::handlers::RingChannel {
    zenoh::handlers::RingChannel::new(4)
}

/// `--control`: sends one control message.
fn send_control(session: &zenoh::Session, keys: &Keys, msg: &str) -> anyhow::Result<()> {
    session
        .put(&keys.control, msg.as_bytes().to_vec())
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh put: {e}"))?;
    // Let the message leave before the session closes.
    std::thread::sleep(Duration::from_millis(200));
    println!("sent control to {}", keys.control);
    Ok(())
}

/// `--status`: asks the service's queryable until it answers or `deadline` passes.
fn print_status(
    session: &zenoh::Session,
    keys: &Keys,
    deadline: Instant,
    seconds: f64,
) -> anyhow::Result<()> {
    while Instant::now() < deadline {
        let replies = session
            .get(&keys.status)
            .timeout(Duration::from_secs(2))
            .wait()
            .map_err(|e| anyhow::anyhow!("zenoh get: {e}"))?;
        if let Ok(reply) = replies.recv()
            && let Ok(sample) = reply.result()
        {
            println!("{}", String::from_utf8_lossy(&sample.payload().to_bytes()));
            return Ok(());
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    anyhow::bail!("no status from {} within {} s", keys.status, seconds);
}

/// Subscribes to the frames until `deadline` or `--frames`, printing a line per frame (unless
/// `--quiet`) and the summary line; `--save` writes the last one.
fn receive_frames(
    args: &SubscribeArgs,
    session: &zenoh::Session,
    keys: &Keys,
    deadline: Instant,
) -> anyhow::Result<()> {
    let sub = session
        .declare_subscriber(&keys.frame)
        .with(newest_frames())
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh subscribe: {e}"))?;
    let (mut received, mut lost, mut bad, mut shm) = (0u64, 0u64, 0u64, 0u64);
    let mut last: Option<(crate::output::ring::FrameMeta, Vec<u8>)> = None;
    let mut prev: Option<u64> = None;
    let mut latency = Vec::new();
    while Instant::now() < deadline && args.frames.is_none_or(|n| received < n) {
        let left = deadline.saturating_duration_since(Instant::now());
        let Ok(Some(sample)) = sub.recv_timeout(left.min(Duration::from_millis(200))) else {
            continue;
        };
        let payload = sample.payload();
        let is_shm = payload.as_shm().is_some();
        let bytes = payload.to_bytes();
        match parse_payload(&bytes) {
            Ok(Payload { meta, pixels, .. }) => {
                let now = monotonic_ns();
                let lat_us = now.saturating_sub(meta.publish_ns) as f64 / 1e3;
                latency.push(lat_us);
                received += 1;
                shm += is_shm as u64;
                if let Some(p) = prev
                    && meta.frame > p
                {
                    lost += meta.frame - p - 1;
                }
                prev = Some(meta.frame);
                if !args.quiet {
                    println!(
                        "frame={} width={} height={} x={} y={} z={} yaw_deg={} pitch_deg={} vfov_deg={} latency_us={lat_us:.0} shm={}",
                        meta.frame,
                        meta.width,
                        meta.height,
                        meta.position[0],
                        meta.position[1],
                        meta.position[2],
                        meta.yaw_deg,
                        meta.pitch_deg,
                        meta.vfov_deg,
                        is_shm as u8
                    );
                }
                if args.save.is_some() {
                    last = Some((meta, pixels.to_vec()));
                }
            }
            Err(e) => {
                bad += 1;
                tracing::warn!("{e}");
            }
        }
    }
    if let (Some(path), Some((meta, pixels))) = (&args.save, &last) {
        crate::output::png::write_png(path, meta.width, meta.height, pixels)?;
    }
    let lat = Percentiles::of(latency);
    println!(
        "received={received} lost={lost} bad={bad} shm={shm} latency_median_us={:.0} latency_p99_us={:.0}",
        lat.median, lat.p99
    );
    drop(sub);
    Ok(())
}
