//! `vkterrain serve`: the headless service. Renders until SIGTERM/SIGINT (or `--frames`) and
//! publishes every frame into the shared-memory ring; the camera follows the scenario (looped)
//! until a control message takes over. `vkterrain status` reads the status file it writes.
//!
//! Control channel: a Unix datagram socket; one JSON object per datagram, e.g.
//! `{"pose":{"position":[x,y,z],"yaw_deg":0,"pitch_deg":-20,"roll_deg":0},"fov_deg":60}`,
//! `{"resolution":[640,360]}`, `{"scripted":true}`,
//! `{"consumer":{"name":"detector","received":100,"lost":3}}`. Anything malformed or out of
//! range is rejected and counted; nothing a client sends can stop the renderer.

use std::collections::{BTreeMap, VecDeque};
use std::os::unix::net::UnixDatagram;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use serde::{Deserialize, Serialize};

use super::render::{RenderArgs, check_validation, prepare};

use crate::output::ring::{Geometry, ProducerOptions, RingProducer, sys};
use crate::render::stats::Percentiles;
use crate::render::{FrameRequest, RenderOptions};
use crate::scene::Camera;

#[derive(Args, Debug, Clone, Default)]
pub struct ServeArgs {
    /// Configuration file (TOML); built-in defaults without one.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Ring (shared-memory segment) name, overrides `ring.name`.
    #[arg(long)]
    pub ring: Option<String>,
    /// Stop after this many frames (tests); default: run until SIGTERM/SIGINT.
    #[arg(long)]
    pub frames: Option<u64>,
    /// Control socket path, overrides `service.control`.
    #[arg(long)]
    pub control: Option<PathBuf>,
    /// Status file path, overrides `service.status_file`.
    #[arg(long)]
    pub status_file: Option<PathBuf>,
    #[arg(long)]
    pub width: Option<u32>,
    #[arg(long)]
    pub height: Option<u32>,
    /// Device override: index or name substring.
    #[arg(long)]
    pub device: Option<String>,
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

/// SIGTERM and SIGINT set [`STOP`]; the loop finishes the frame in flight and shuts down.
fn install_signal_handlers() -> anyhow::Result<()> {
    for sig in [libc::SIGTERM, libc::SIGINT] {
        // SAFETY: the handler only stores to an atomic (async-signal-safe).
        let r = unsafe {
            let mut sa: libc::sigaction = std::mem::zeroed();
            sa.sa_sigaction = on_signal as *const () as usize;
            libc::sigemptyset(&mut sa.sa_mask);
            libc::sigaction(sig, &sa, std::ptr::null_mut())
        };
        if r != 0 {
            anyhow::bail!(
                "cannot install signal handler: {}",
                std::io::Error::last_os_error()
            );
        }
    }
    Ok(())
}

/// Largest accepted position coordinate (metres): far beyond any data set, finite.
const MAX_COORD_M: f64 = 1.0e7;
/// Accepted resolution change range per side.
const RES_RANGE: std::ops::RangeInclusive<u32> = 16..=8192;
/// Control datagrams handled per frame at most, so a flood cannot starve rendering.
const MAX_MESSAGES_PER_FRAME: usize = 256;
/// Consumers remembered in the status.
const MAX_CONSUMERS: usize = 64;
/// Frame intervals the status percentiles are taken over.
const WINDOW: usize = 512;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ControlMsg {
    pose: Option<Pose>,
    fov_deg: Option<f64>,
    resolution: Option<[u32; 2]>,
    scripted: Option<bool>,
    consumer: Option<ConsumerReport>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Pose {
    position: [f64; 3],
    yaw_deg: f64,
    pitch_deg: f64,
    #[serde(default)]
    roll_deg: f64,
}

#[derive(Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct ConsumerReport {
    name: String,
    received: u64,
    lost: u64,
}

/// What the render loop should change after a control message.
#[derive(Default)]
struct Control {
    live: Option<Camera>,
    resize: Option<(u32, u32)>,
    accepted: u64,
    rejected: u64,
    last_error: Option<String>,
    consumers: BTreeMap<String, ConsumerReport>,
}

impl Control {
    /// Applies one datagram; errors are reasons to reject it (counted by the caller).
    fn apply(&mut self, bytes: &[u8], current: &Camera) -> Result<(), String> {
        let text = std::str::from_utf8(bytes).map_err(|_| "not UTF-8".to_string())?;
        let msg: ControlMsg = serde_json::from_str(text.trim()).map_err(|e| e.to_string())?;
        let mut cam = self.live.unwrap_or(*current);
        let mut changed = false;
        if let Some(p) = &msg.pose {
            if p.position
                .iter()
                .any(|v| !v.is_finite() || v.abs() > MAX_COORD_M)
            {
                return Err(format!("position outside +-{MAX_COORD_M} m"));
            }
            cam.position = glam::DVec3::from_array(p.position);
            (cam.yaw_deg, cam.pitch_deg, cam.roll_deg) = (p.yaw_deg, p.pitch_deg, p.roll_deg);
            if !(cam.yaw_deg.abs() <= 3600.0 && cam.roll_deg.abs() <= 3600.0) {
                return Err("yaw/roll outside +-3600 deg".into());
            }
            changed = true;
        }
        if let Some(f) = msg.fov_deg {
            if !(f.is_finite() && (1.0..=170.0).contains(&f)) {
                return Err(format!("fov_deg {f} is outside 1..=170"));
            }
            cam.vfov_deg = f;
            changed = true;
        }
        cam.validate().map_err(|e| e.to_string())?;
        let resize = match msg.resolution {
            Some([w, h]) if RES_RANGE.contains(&w) && RES_RANGE.contains(&h) => Some((w, h)),
            Some([w, h]) => {
                return Err(format!(
                    "resolution {w}x{h} is outside {RES_RANGE:?} per side"
                ));
            }
            None => None,
        };
        if let Some(c) = &msg.consumer
            && (c.name.is_empty()
                || c.name.len() > 64
                || c.name.chars().any(char::is_control)
                || (self.consumers.len() >= MAX_CONSUMERS && !self.consumers.contains_key(&c.name)))
        {
            return Err("consumer report: bad name or too many consumers".into());
        }
        if msg.pose.is_none()
            && msg.fov_deg.is_none()
            && resize.is_none()
            && msg.scripted.is_none()
            && msg.consumer.is_none()
        {
            return Err("empty message".into());
        }
        // Everything checked: apply.
        if changed {
            self.live = Some(cam);
        }
        if msg.scripted == Some(true) {
            self.live = None;
        }
        if resize.is_some() {
            self.resize = resize;
        }
        if let Some(c) = msg.consumer {
            self.consumers.insert(c.name.clone(), c);
        }
        Ok(())
    }
}

/// Binds the control socket (mode 0600), replacing a stale socket but nothing else.
fn bind_control(path: &Path) -> anyhow::Result<UnixDatagram> {
    use std::os::unix::fs::{FileTypeExt, PermissionsExt};
    if let Ok(m) = std::fs::symlink_metadata(path) {
        if m.file_type().is_socket() {
            std::fs::remove_file(path).with_context(|| format!("{}", path.display()))?;
        } else {
            anyhow::bail!("{}: exists and is not a socket", path.display());
        }
    }
    let sock = UnixDatagram::bind(path)
        .with_context(|| format!("{}: cannot bind control socket", path.display()))?;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o600))
        .with_context(|| format!("{}", path.display()))?;
    sock.set_nonblocking(true)?;
    Ok(sock)
}

/// Removes a file when dropped (the control socket).
struct RemoveOnDrop(PathBuf);

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// What `status.json` holds.
#[derive(Serialize, Deserialize, Debug, Clone)]
pub struct Status {
    pub state: String,
    pub pid: u32,
    pub ring: String,
    pub generation: u64,
    pub device: String,
    pub dataset: String,
    pub width: u32,
    pub height: u32,
    pub frames_rendered: u64,
    pub frame_ms_median: f64,
    pub frame_ms_p99: f64,
    pub camera: String,
    pub control_accepted: u64,
    pub control_rejected: u64,
    pub control_last_error: Option<String>,
    /// Consumers that reported over the control socket: frames received and skipped.
    pub consumers: BTreeMap<String, (u64, u64)>,
    /// Streaming state when heights come through the clipmap.
    #[serde(default)]
    pub clipmap: Option<ClipmapStatus>,
    pub uptime_s: f64,
    pub updated_unix_ms: u64,
}

/// The clipmap's streaming counters in `status.json`: whether data is missing, failing or
/// arriving (`docs/clipmap.md`).
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
pub struct ClipmapStatus {
    pub atlas_capacity: u32,
    pub resident_nodes: usize,
    pub loaded: u64,
    pub load_errors: u64,
    pub deferred: u64,
    pub evictions: u64,
    pub fallback_frames: u64,
}

impl ClipmapStatus {
    fn of(c: &crate::clipmap::Clipmap) -> Self {
        ClipmapStatus {
            atlas_capacity: c.settings.atlas_capacity,
            resident_nodes: c.atlas.resident(),
            loaded: c.counters.loaded,
            load_errors: c.counters.load_errors,
            deferred: c.counters.deferred,
            evictions: c.counters.evictions,
            fallback_frames: c.counters.fallback_frames,
        }
    }
}

fn make_ring(
    name: &str,
    opts: &RenderOptions,
    slots: u32,
    popts: &ProducerOptions,
) -> anyhow::Result<RingProducer> {
    Ok(RingProducer::create(
        name,
        Geometry {
            width: opts.width,
            height: opts.height,
            slot_count: slots,
            depth: opts.readback_depth,
        },
        popts,
    )?)
}

pub fn run(args: &ServeArgs) -> anyhow::Result<()> {
    let p = prepare(&RenderArgs {
        config: args.config.clone(),
        width: args.width,
        height: args.height,
        device: args.device.clone(),
        ..Default::default()
    })?;
    let mut config = p.config;
    if let Some(r) = &args.ring {
        crate::output::ring::validate_name(r)?;
        config.ring.name = r.clone();
    }
    let control_path = args
        .control
        .clone()
        .or_else(|| config.service.control.as_ref().map(|c| config.resolve(c)));
    let status_path = args.status_file.clone().or_else(|| {
        config
            .service
            .status_file
            .as_ref()
            .map(|c| config.resolve(c))
    });
    let popts = ProducerOptions {
        group: config
            .ring
            .group
            .as_deref()
            .map(sys::group_id)
            .transpose()?,
        keep_segment: config.ring.keep_segment,
    };
    install_signal_handlers()?;
    // Bind first: a bad path fails before the (slow) device start-up; removed on every exit.
    let control = control_path.as_deref().map(bind_control).transpose()?;
    let _socket_guard = control_path.clone().map(RemoveOnDrop);

    let gpu = config.open_gpu()?;
    let mut options = config.render_options();
    let mut renderer = config.open_renderer(&gpu, &p.data, options.clone())?;
    let mut ring = make_ring(&config.ring.name, &options, config.ring.slots, &popts)?;
    tracing::info!(
        ring = config.ring.name,
        device = gpu.info.name,
        dataset = p.data.name(),
        width = options.width,
        height = options.height,
        "serving"
    );

    let started = Instant::now();
    let mut ctl = Control::default();
    let mut intervals: VecDeque<f64> = VecDeque::with_capacity(WINDOW);
    let mut rendered: u64 = 0;
    let mut last_status = Instant::now() - Duration::from_secs(3600);
    let status_every = Duration::from_secs_f64(config.service.status_interval_s);
    let frame_budget = (config.service.max_fps > 0.0)
        .then(|| Duration::from_secs_f64(1.0 / config.service.max_fps));
    let scripted_frames = p.scenario.frames.max(1) as u64;
    let mut buf = vec![0u8; 65536];
    let mut camera = p.scenario.camera(0);

    let status = |state: &str,
                  ring: &RingProducer,
                  options: &RenderOptions,
                  ctl: &Control,
                  intervals: &VecDeque<f64>,
                  rendered: u64,
                  clipmap: Option<ClipmapStatus>|
     -> Status {
        let pc = Percentiles::of(intervals.iter().copied().collect());
        Status {
            state: state.into(),
            pid: std::process::id(),
            ring: ring.name().into(),
            generation: ring.generation(),
            device: gpu.info.name.clone(),
            dataset: p.data.name().to_string(),
            width: options.width,
            height: options.height,
            frames_rendered: rendered,
            frame_ms_median: pc.median,
            frame_ms_p99: pc.p99,
            camera: if ctl.live.is_some() {
                "control".into()
            } else {
                format!("scripted ({})", p.scenario.name)
            },
            control_accepted: ctl.accepted,
            control_rejected: ctl.rejected,
            control_last_error: ctl.last_error.clone(),
            consumers: ctl
                .consumers
                .iter()
                .map(|(k, v)| (k.clone(), (v.received, v.lost)))
                .collect(),
            clipmap,
            uptime_s: started.elapsed().as_secs_f64(),
            updated_unix_ms: sys::realtime_ns() / 1_000_000,
        }
    };
    let write_status = |s: &Status| {
        if let Some(path) = &status_path {
            let text = serde_json::to_string_pretty(s).unwrap_or_default();
            if let Err(e) = crate::output::write_atomic(path, text.as_bytes()) {
                tracing::warn!("status file: {e}");
            }
        }
    };

    let result = (|| -> anyhow::Result<()> {
        while !STOP.load(Ordering::SeqCst) && args.frames.is_none_or(|n| rendered < n) {
            let frame_start = Instant::now();
            if let Some(sock) = &control {
                for _ in 0..MAX_MESSAGES_PER_FRAME {
                    match sock.recv(&mut buf) {
                        Ok(n) if n < buf.len() => match ctl.apply(&buf[..n], &camera) {
                            Ok(()) => ctl.accepted += 1,
                            Err(e) => {
                                ctl.rejected += 1;
                                if ctl.rejected <= 10 {
                                    tracing::warn!("control message rejected: {e}");
                                }
                                ctl.last_error = Some(e);
                            }
                        },
                        Ok(_) => {
                            ctl.rejected += 1;
                            ctl.last_error = Some("message too long".into());
                        }
                        Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => break,
                        Err(e) => {
                            tracing::warn!("control socket: {e}");
                            break;
                        }
                    }
                }
            }
            if let Some((w, h)) = ctl.resize.take()
                && (w, h) != (options.width, options.height)
            {
                // Deliver what is in flight, then a new renderer and a new ring generation.
                renderer.finish(&mut ring)?;
                options.width = w;
                options.height = h;
                // A fresh clipmap too: its atlas lives in the old renderer's device memory.
                renderer = config.open_renderer(&gpu, &p.data, options.clone())?;
                ring = make_ring(&config.ring.name, &options, config.ring.slots, &popts)?;
                tracing::info!(width = w, height = h, "resolution changed");
            }
            camera = ctl
                .live
                .unwrap_or_else(|| p.scenario.camera(rendered % scripted_frames));
            let views = FrameRequest::with_extra_views(camera, &config.render.extra_views);
            renderer.render_views(&views, &mut ring)?;
            rendered += 1;
            for rec in renderer.stats.frames.drain(..) {
                if rec.interval_ms > 0.0 {
                    if intervals.len() == WINDOW {
                        intervals.pop_front();
                    }
                    intervals.push_back(rec.interval_ms);
                }
            }
            if last_status.elapsed() >= status_every {
                write_status(&status(
                    "running",
                    &ring,
                    &options,
                    &ctl,
                    &intervals,
                    rendered,
                    renderer.clipmap().map(ClipmapStatus::of),
                ));
                last_status = Instant::now();
            }
            if let Some(budget) = frame_budget {
                let spent = frame_start.elapsed();
                if spent < budget {
                    std::thread::sleep(budget - spent);
                }
            }
        }
        // The frames in flight are finished and published before the ring closes.
        renderer.finish(&mut ring)?;
        Ok(())
    })();
    ring.close();
    write_status(&status(
        "stopped",
        &ring,
        &options,
        &ctl,
        &intervals,
        rendered,
        renderer.clipmap().map(ClipmapStatus::of),
    ));
    result?;
    drop(renderer);
    check_validation(&gpu)?;
    tracing::info!(frames = rendered, "stopped");
    Ok(())
}

#[derive(Args, Debug, Clone, Default)]
pub struct StatusArgs {
    /// Status file written by `vkterrain serve`.
    #[arg(long)]
    pub status_file: Option<PathBuf>,
    /// Also (or only) read a ring's header directly.
    #[arg(long)]
    pub ring: Option<String>,
}

/// `vkterrain status`: prints the service status file and/or a ring's header.
pub fn status(args: &StatusArgs) -> anyhow::Result<()> {
    if args.status_file.is_none() && args.ring.is_none() {
        anyhow::bail!("status needs --status-file PATH and/or --ring NAME");
    }
    if let Some(path) = &args.status_file {
        let text = std::fs::read_to_string(path).map_err(|e| crate::Error::io(path, e))?;
        let s: Status = serde_json::from_str(&text).map_err(|e| {
            crate::Error::invalid("status file", format!("{}: {e}", path.display()))
        })?;
        let age_s = (sys::realtime_ns() / 1_000_000).saturating_sub(s.updated_unix_ms) as f64 / 1e3;
        let state = if s.state == "running" && !sys::pid_alive(s.pid) {
            "dead (process gone without stopping)".to_string()
        } else {
            s.state.clone()
        };
        println!(
            "state:           {state} (pid {}, updated {age_s:.1} s ago)",
            s.pid
        );
        println!("ring:            {} (generation {})", s.ring, s.generation);
        println!("device:          {}", s.device);
        println!("dataset:         {}", s.dataset);
        println!("resolution:      {}x{}", s.width, s.height);
        println!("frames rendered: {}", s.frames_rendered);
        println!(
            "frame time:      median {:.2} ms, p99 {:.2} ms",
            s.frame_ms_median, s.frame_ms_p99
        );
        println!("camera:          {}", s.camera);
        println!(
            "control:         {} accepted, {} rejected{}",
            s.control_accepted,
            s.control_rejected,
            s.control_last_error
                .as_deref()
                .map(|e| format!(" (last: {e})"))
                .unwrap_or_default()
        );
        if let Some(c) = &s.clipmap {
            println!(
                "clipmap:         {}/{} nodes resident; {} loaded, {} load errors, {} deferred, {} evictions, {} frames with fallback data",
                c.resident_nodes,
                c.atlas_capacity,
                c.loaded,
                c.load_errors,
                c.deferred,
                c.evictions,
                c.fallback_frames
            );
        }
        for (name, (received, lost)) in &s.consumers {
            println!("consumer:        {name}: {received} received, {lost} skipped");
        }
        println!("uptime:          {:.1} s", s.uptime_s);
    }
    if let Some(name) = &args.ring {
        let r = crate::output::ring::RingReader::open(name)?;
        let g = r.geometry();
        let state = match r.state() {
            1 => "live",
            2 => "closed",
            3 => "replaced",
            _ => "unknown",
        };
        println!(
            "ring {name}:       {state}, generation {}, {}x{} RGBA8, {} slots{}, latest frame {}",
            r.generation(),
            g.width,
            g.height,
            g.slot_count,
            if g.depth { " + depth" } else { "" },
            r.latest().map_or("none".into(), |l| l.to_string())
        );
    }
    Ok(())
}
