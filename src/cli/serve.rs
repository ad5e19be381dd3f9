//! `vkterrain serve`: the headless service. Renders until SIGTERM/SIGINT (or `--frames`) and
//! publishes every frame into the shared-memory ring (and over Zenoh when enabled); the camera
//! follows the scenario (looped) until a control message takes over (`service::control`).
//! `vkterrain status` reads the status file it writes.

use std::collections::{BTreeMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use clap::Args;
use serde::{Deserialize, Serialize};

use super::render::{Prepared, RenderArgs, check_validation, prepare};
use crate::config::Config;
use crate::dataset::Terrain;
use crate::driver::Gpu;
use crate::output::lock::{PathLock, lock_path_for};
use crate::output::ring::{
    Geometry, ProducerOptions, RingLocation, RingProducer, ZeroCopyRequest, sys,
};
use crate::readback::{DirectTarget, FrameSink, FrameView};
use crate::render::stats::Percentiles;
use crate::render::{FrameRequest, RenderOptions, Renderer};
use crate::scene::{Camera, Scenario};
use crate::service::control::{Control, ControlSocket};

#[derive(Args, Debug, Clone, Default)]
pub struct ServeArgs {
    /// Configuration file (TOML); built-in defaults without one.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Ring name, overrides `ring.name`.
    #[arg(long)]
    pub ring: Option<String>,
    /// Ring directory, overrides `ring.dir` (default `$VKTERRAIN_RING_DIR` or /run/vkterrain).
    #[arg(long)]
    pub ring_dir: Option<PathBuf>,
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
    /// Publish over Zenoh too (`zenoh.enabled`).
    #[arg(long)]
    pub zenoh: bool,
    /// Zenoh endpoint to listen on (repeatable), e.g. tcp/127.0.0.1:7447.
    #[arg(long)]
    pub zenoh_listen: Vec<String>,
    /// Zenoh endpoint to connect to (repeatable).
    #[arg(long)]
    pub zenoh_connect: Vec<String>,
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

/// Frame intervals the status percentiles are taken over.
const WINDOW: usize = 512;
/// Largest status file `vkterrain status` reads.
const MAX_STATUS_BYTES: u64 = 1 << 20;

/// The status file, ours while we live (`<path>.lock`): a second service refuses it. An
/// existing path must be a regular file (never `/dev/zero` or a device replaced by rename).
fn claim_status_file(path: &Path) -> anyhow::Result<PathLock> {
    if let Ok(m) = std::fs::symlink_metadata(path)
        && !m.file_type().is_file()
    {
        anyhow::bail!(
            "{}: exists and is not a regular file; refusing to replace it with the status",
            path.display()
        );
    }
    Ok(PathLock::acquire(
        &lock_path_for(path),
        &format!("status file {}", path.display()),
    )?)
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
    /// The ring's directory (the segment is `<ring_dir>/<ring>`).
    #[serde(default)]
    pub ring_dir: String,
    /// The GPU writes frames straight into the ring slots.
    #[serde(default)]
    pub zero_copy: bool,
    /// Why zero-copy is off although the device could do it, if so.
    #[serde(default)]
    pub zero_copy_note: Option<String>,
    /// Median host time to publish a frame into the ring (and Zenoh), last 512 frames.
    #[serde(default)]
    pub publish_ms_median: f64,
    /// Zenoh: frames published / dropped (slow network or subscriber), when enabled.
    #[serde(default)]
    pub zenoh: Option<ZenohStatus>,
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

/// Zenoh counters in `status.json`.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
pub struct ZenohStatus {
    pub key: String,
    pub published: u64,
    pub dropped: u64,
    pub shm_frames: u64,
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

/// The ring's geometry for the renderer's frames: page-aligned slots, or what the device needs
/// to import them (zero-copy).
fn ring_geometry(opts: &RenderOptions, slots: u32, popts: &ProducerOptions) -> Geometry {
    let device_align = popts
        .zero_copy
        .as_ref()
        .map_or(0, |z| z.gpu.info.host_pointer_alignment);
    let align = (crate::output::ring::layout::SLOT_ALIGN as u64)
        .max(device_align.next_power_of_two())
        .min(crate::output::ring::layout::MAX_ALIGN as u64) as u32;
    Geometry {
        align,
        ..Geometry::new(opts.width, opts.height, slots, opts.readback_depth)
    }
}

fn make_ring(
    location: &RingLocation,
    opts: &RenderOptions,
    slots: u32,
    popts: &ProducerOptions,
) -> anyhow::Result<RingProducer> {
    Ok(RingProducer::create(
        location,
        ring_geometry(opts, slots, popts),
        popts,
    )?)
}

/// Every frame to the ring and, when enabled, to Zenoh; zero-copy targets come from the ring.
struct Outputs<'a> {
    ring: &'a mut RingProducer,
    #[cfg(feature = "zenoh")]
    zenoh: Option<&'a mut crate::service::zenoh::ZenohBridge>,
    publish_ms: &'a mut VecDeque<f64>,
}

impl FrameSink for Outputs<'_> {
    fn frame(&mut self, frame: &FrameView<'_>) -> crate::Result<()> {
        let start = Instant::now();
        self.ring.frame(frame)?;
        #[cfg(feature = "zenoh")]
        if let Some(z) = self.zenoh.as_deref_mut() {
            z.publish(frame);
        }
        if self.publish_ms.len() == WINDOW {
            self.publish_ms.pop_front();
        }
        self.publish_ms
            .push_back(start.elapsed().as_secs_f64() * 1e3);
        Ok(())
    }

    fn direct_target(&mut self, index: u64, bytes: u64) -> Option<DirectTarget> {
        self.ring.direct_target(index, bytes)
    }
}

#[cfg(feature = "zenoh")]
type Zenoh = crate::service::zenoh::ZenohBridge;
/// Without the `zenoh` feature there is never a bridge (`start_zenoh` refuses to start one).
#[cfg(not(feature = "zenoh"))]
struct Zenoh;

fn start_zenoh(config: &crate::config::Config, ring: &str) -> anyhow::Result<Option<Zenoh>> {
    if !config.zenoh.enabled {
        return Ok(None);
    }
    #[cfg(feature = "zenoh")]
    {
        Ok(Some(crate::service::zenoh::ZenohBridge::start(
            &config.zenoh,
            ring,
        )?))
    }
    #[cfg(not(feature = "zenoh"))]
    {
        let _ = ring;
        anyhow::bail!("zenoh.enabled, but this build has no Zenoh (cargo feature `zenoh`)")
    }
}

/// Applies the command line's ring and Zenoh overrides to the config, and checks them.
fn apply_overrides(config: &mut Config, args: &ServeArgs) -> anyhow::Result<()> {
    if let Some(r) = &args.ring {
        crate::output::ring::validate_name(r)?;
        config.ring.name = r.clone();
    }
    if let Some(d) = &args.ring_dir {
        config.ring.dir = Some(d.clone());
    }
    config.zenoh.enabled |= args.zenoh;
    config
        .zenoh
        .listen
        .extend(args.zenoh_listen.iter().cloned());
    config
        .zenoh
        .connect
        .extend(args.zenoh_connect.iter().cloned());
    config.zenoh.validate()?;
    Ok(())
}

/// Where the service publishes and listens, resolved (and checked) before anything is opened.
struct Endpoints {
    location: RingLocation,
    control: Option<PathBuf>,
    status: Option<PathBuf>,
    /// The group allowed to read the ring (`ring.group`).
    group: Option<u32>,
}

impl Endpoints {
    fn of(config: &Config, args: &ServeArgs) -> anyhow::Result<Self> {
        let location = RingLocation::new(
            config
                .ring
                .dir
                .as_ref()
                .map(|d| config.resolve(d))
                .unwrap_or_else(crate::output::ring::location::default_dir),
            &config.ring.name,
        )?;
        let control = args
            .control
            .clone()
            .or_else(|| config.service.control.as_ref().map(|c| config.resolve(c)));
        let status = args.status_file.clone().or_else(|| {
            config
                .service
                .status_file
                .as_ref()
                .map(|c| config.resolve(c))
        });
        let group = config
            .ring
            .group
            .as_deref()
            .map(sys::group_id)
            .transpose()?;
        Ok(Endpoints {
            location,
            control,
            status,
            group,
        })
    }
}

/// Where frames go: the ring and, when enabled, Zenoh; with the publish times of the last
/// [`WINDOW`] frames. Kept apart from the renderer so both can be borrowed at once.
struct Sinks {
    ring: RingProducer,
    zenoh: Option<Zenoh>,
    publish_ms: VecDeque<f64>,
}

impl Sinks {
    fn outputs(&mut self) -> Outputs<'_> {
        Outputs {
            ring: &mut self.ring,
            #[cfg(feature = "zenoh")]
            zenoh: self.zenoh.as_mut(),
            publish_ms: &mut self.publish_ms,
        }
    }
}

#[allow(unused_variables)]
fn zenoh_status(z: &Option<Zenoh>) -> Option<ZenohStatus> {
    #[cfg(feature = "zenoh")]
    {
        z.as_ref().map(|z| ZenohStatus {
            key: z.keys().frame.clone(),
            published: z.counters.published.load(Ordering::Relaxed),
            dropped: z.counters.dropped.load(Ordering::Relaxed),
            shm_frames: z.counters.shm_frames.load(Ordering::Relaxed),
        })
    }
    #[cfg(not(feature = "zenoh"))]
    None
}

/// Control messages with WGS84 poses, when the data set lies on the earth.
fn control_for(config: &Config, data: &Terrain) -> anyhow::Result<Control> {
    let mut ctl = Control::default();
    if let Some(earth) = config.open_earth()? {
        let data = data.clone();
        ctl.geo = Some(Box::new(
            move |pose: &crate::geo::GeoPose, current: &crate::scene::Camera| {
                earth.camera(pose, &data, current)
            },
        ));
    }
    Ok(ctl)
}

/// A running service: the renderer and where its frames go, the control state that steers the
/// camera, and the counters `status.json` reports.
struct Service<'a> {
    config: &'a Config,
    gpu: &'a Arc<Gpu>,
    data: &'a Terrain,
    scenario: &'a Scenario,
    popts: ProducerOptions,
    options: RenderOptions,
    renderer: Renderer,
    sinks: Sinks,
    control: Option<ControlSocket>,
    ctl: Control,
    camera: Camera,
    /// Frame intervals of the last [`WINDOW`] frames.
    intervals: VecDeque<f64>,
    rendered: u64,
    started: Instant,
    status_path: Option<PathBuf>,
}

impl<'a> Service<'a> {
    /// Opens the renderer, the ring and Zenoh on `gpu`.
    fn start(
        p: &'a Prepared,
        gpu: &'a Arc<Gpu>,
        ends: Endpoints,
        control: Option<ControlSocket>,
    ) -> anyhow::Result<Self> {
        let config = &p.config;
        let options = config.render_options();
        let popts = ProducerOptions {
            group: ends.group,
            keep_segment: config.ring.keep_segment,
            zero_copy: config.ring.zero_copy.then(|| ZeroCopyRequest {
                gpu: gpu.clone(),
                frames_in_flight: options.frames_in_flight,
            }),
        };
        let renderer = config.open_renderer(gpu, &p.data, options.clone())?;
        let ring = make_ring(&ends.location, &options, config.ring.slots, &popts)?;
        let zenoh = start_zenoh(config, &config.ring.name)?;
        tracing::info!(
            ring = %ends.location,
            zero_copy = ring.zero_copy(),
            device = gpu.info.name,
            dataset = p.data.name(),
            width = options.width,
            height = options.height,
            "serving"
        );
        let started = Instant::now();
        Ok(Service {
            config,
            gpu,
            data: &p.data,
            scenario: &p.scenario,
            popts,
            options,
            renderer,
            sinks: Sinks {
                ring,
                zenoh,
                publish_ms: VecDeque::with_capacity(WINDOW),
            },
            control,
            ctl: control_for(config, &p.data)?,
            camera: p.scenario.camera(0),
            intervals: VecDeque::with_capacity(WINDOW),
            rendered: 0,
            started,
            status_path: ends.status,
        })
    }

    /// Renders until SIGTERM/SIGINT or `frames`, writing the status every
    /// `service.status_interval_s` and keeping to `service.max_fps`.
    fn serve(&mut self, frames: Option<u64>) -> anyhow::Result<()> {
        let mut last_status = Instant::now() - Duration::from_secs(3600);
        let status_every = Duration::from_secs_f64(self.config.service.status_interval_s);
        let frame_budget = (self.config.service.max_fps > 0.0)
            .then(|| Duration::from_secs_f64(1.0 / self.config.service.max_fps));
        while !STOP.load(Ordering::SeqCst) && frames.is_none_or(|n| self.rendered < n) {
            let frame_start = Instant::now();
            self.take_control()?;
            self.render_frame()?;
            if last_status.elapsed() >= status_every {
                self.write_status("running");
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
        self.renderer.finish(&mut self.sinks.outputs())?;
        Ok(())
    }

    /// Reads the control messages waiting (socket and Zenoh) and applies a resize they ask for.
    fn take_control(&mut self) -> anyhow::Result<()> {
        if let Some(sock) = &mut self.control {
            sock.drain(&mut self.ctl, &self.camera);
        }
        #[cfg(feature = "zenoh")]
        if let Some(z) = &mut self.sinks.zenoh {
            z.drain_control(&mut self.ctl, &self.camera);
        }
        if let Some((w, h)) = self.ctl.resize.take()
            && (w, h) != (self.options.width, self.options.height)
        {
            // Deliver what is in flight, then a new renderer and a new ring generation.
            self.renderer.finish(&mut self.sinks.outputs())?;
            self.options.width = w;
            self.options.height = h;
            // A fresh clipmap too: its atlas lives in the old renderer's device memory.
            self.renderer = self
                .config
                .open_renderer(self.gpu, self.data, self.options.clone())?;
            let geometry = ring_geometry(&self.options, self.config.ring.slots, &self.popts);
            self.sinks.ring.replace(geometry, &self.popts)?;
            tracing::info!(width = w, height = h, "resolution changed");
        }
        Ok(())
    }

    /// Renders the next frame from the live camera (or the looped scenario) and publishes it.
    fn render_frame(&mut self) -> anyhow::Result<()> {
        let scripted_frames = self.scenario.frames.max(1) as u64;
        self.camera = self
            .ctl
            .live
            .unwrap_or_else(|| self.scenario.camera(self.rendered % scripted_frames));
        let views = FrameRequest::with_extra_views_on(
            self.camera,
            &self.config.render.extra_views,
            self.renderer.earth_frame(),
        );
        self.renderer
            .render_views(&views, &mut self.sinks.outputs())?;
        self.rendered += 1;
        for rec in self.renderer.stats.frames.drain(..) {
            if rec.interval_ms > 0.0 {
                if self.intervals.len() == WINDOW {
                    self.intervals.pop_front();
                }
                self.intervals.push_back(rec.interval_ms);
            }
        }
        Ok(())
    }

    fn status(&self, state: &str) -> Status {
        let pc = Percentiles::of(self.intervals.iter().copied().collect());
        let pub_ms = Percentiles::of(self.sinks.publish_ms.iter().copied().collect());
        let ring = &self.sinks.ring;
        let ctl = &self.ctl;
        Status {
            state: state.into(),
            pid: std::process::id(),
            ring: ring.name().into(),
            generation: ring.generation(),
            device: self.gpu.info.name.clone(),
            dataset: self.data.name().to_string(),
            width: self.options.width,
            height: self.options.height,
            frames_rendered: self.rendered,
            frame_ms_median: pc.median,
            frame_ms_p99: pc.p99,
            camera: if ctl.live.is_some() {
                "control".into()
            } else {
                format!("scripted ({})", self.scenario.name)
            },
            control_accepted: ctl.accepted,
            control_rejected: ctl.rejected,
            control_last_error: ctl.last_error.clone(),
            consumers: ctl.consumers(),
            clipmap: self.renderer.clipmap().map(ClipmapStatus::of),
            ring_dir: ring.location().dir.display().to_string(),
            zero_copy: ring.zero_copy(),
            zero_copy_note: ring.zero_copy_note().map(String::from),
            publish_ms_median: pub_ms.median,
            zenoh: zenoh_status(&self.sinks.zenoh),
            uptime_s: self.started.elapsed().as_secs_f64(),
            updated_unix_ms: sys::realtime_ns() / 1_000_000,
        }
    }

    /// The status to the status file and to Zenoh; a failed write is only a warning.
    fn write_status(&self, state: &str) {
        let text = serde_json::to_string_pretty(&self.status(state)).unwrap_or_default();
        #[cfg(feature = "zenoh")]
        if let Some(z) = &self.sinks.zenoh {
            z.set_status(text.clone());
        }
        if let Some(path) = &self.status_path
            && let Err(e) = crate::output::write_atomic(path, text.as_bytes())
        {
            tracing::warn!("status file: {e}");
        }
    }

    /// Closes the ring, writes the final status, then reports the loop's `result` and the
    /// validation messages.
    fn shut_down(mut self, result: anyhow::Result<()>) -> anyhow::Result<()> {
        // No GPU work may still write into the ring when it closes (zero-copy).
        let _ = self.gpu.wait_idle();
        self.sinks.ring.close();
        self.write_status("stopped");
        let Service {
            gpu,
            renderer,
            sinks: Sinks { ring, zenoh, .. },
            rendered,
            ..
        } = self;
        drop(zenoh);
        result?;
        drop(renderer);
        drop(ring);
        check_validation(gpu)?;
        tracing::info!(frames = rendered, "stopped");
        Ok(())
    }
}

pub fn run(args: &ServeArgs) -> anyhow::Result<()> {
    let mut p = prepare(&RenderArgs {
        config: args.config.clone(),
        width: args.width,
        height: args.height,
        device: args.device.clone(),
        ..Default::default()
    })?;
    apply_overrides(&mut p.config, args)?;
    let ends = Endpoints::of(&p.config, args)?;
    install_signal_handlers()?;
    // Claim the paths first: a bad or taken path fails before the (slow) device start-up.
    let _status_lock = ends.status.as_deref().map(claim_status_file).transpose()?;
    let control = ends
        .control
        .as_deref()
        .map(ControlSocket::bind)
        .transpose()?;

    let gpu = p.config.open_gpu()?;
    let mut service = Service::start(&p, &gpu, ends, control)?;
    let result = service.serve(args.frames);
    service.shut_down(result)
}

#[derive(Args, Debug, Clone, Default)]
pub struct StatusArgs {
    /// Status file written by `vkterrain serve`.
    #[arg(long)]
    pub status_file: Option<PathBuf>,
    /// Also (or only) read a ring's header directly.
    #[arg(long)]
    pub ring: Option<String>,
    /// The ring's directory (default `$VKTERRAIN_RING_DIR` or /run/vkterrain).
    #[arg(long)]
    pub ring_dir: Option<PathBuf>,
    /// User (name or uid) the ring must belong to (default: the ring directory's owner).
    #[arg(long)]
    pub ring_owner: Option<String>,
}

/// Reads a status file: a regular file of at most [`MAX_STATUS_BYTES`], never more.
fn read_status_file(path: &Path) -> crate::Result<Status> {
    use std::io::Read;
    let f = std::fs::File::open(path).map_err(|e| crate::Error::io(path, e))?;
    let m = f.metadata().map_err(|e| crate::Error::io(path, e))?;
    if !m.is_file() {
        return Err(crate::Error::invalid(
            "status file",
            format!("{}: not a regular file", path.display()),
        ));
    }
    let mut text = String::new();
    f.take(MAX_STATUS_BYTES + 1)
        .read_to_string(&mut text)
        .map_err(|e| crate::Error::io(path, e))?;
    if text.len() as u64 > MAX_STATUS_BYTES {
        return Err(crate::Error::invalid(
            "status file",
            format!("{}: larger than {MAX_STATUS_BYTES} bytes", path.display()),
        ));
    }
    serde_json::from_str(&text)
        .map_err(|e| crate::Error::invalid("status file", format!("{}: {e}", path.display())))
}

/// `vkterrain status`: prints the service status file and/or a ring's header.
pub fn status(args: &StatusArgs) -> anyhow::Result<()> {
    if args.status_file.is_none() && args.ring.is_none() {
        anyhow::bail!("status needs --status-file PATH and/or --ring NAME");
    }
    if let Some(path) = &args.status_file {
        let s = read_status_file(path)?;
        print_service_status(&s);
    }
    if let Some(name) = &args.ring {
        print_ring_header(args, name)?;
    }
    Ok(())
}

/// The status file's report: the service's state, output and frame times, its counters,
/// and its uptime.
fn print_service_status(s: &Status) {
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
    println!(
        "ring:            {} in {} (generation {}, {})",
        s.ring,
        s.ring_dir,
        s.generation,
        if s.zero_copy { "zero-copy" } else { "copied" }
    );
    if let Some(n) = &s.zero_copy_note {
        println!("zero-copy off:   {n}");
    }
    println!("device:          {}", s.device);
    println!("dataset:         {}", s.dataset);
    println!("resolution:      {}x{}", s.width, s.height);
    println!("frames rendered: {}", s.frames_rendered);
    println!(
        "frame time:      median {:.2} ms, p99 {:.2} ms; publish median {:.3} ms",
        s.frame_ms_median, s.frame_ms_p99, s.publish_ms_median
    );
    println!("camera:          {}", s.camera);
    print_service_counters(s);
    println!("uptime:          {:.1} s", s.uptime_s);
}

/// The status file's counters: control commands, clipmap streaming, Zenoh publishing and the
/// consumers' reports.
fn print_service_counters(s: &Status) {
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
    if let Some(z) = &s.zenoh {
        println!(
            "zenoh:           {}: {} published ({} in shared memory), {} dropped",
            z.key, z.published, z.shm_frames, z.dropped
        );
    }
    for (name, (received, lost)) in &s.consumers {
        println!("consumer:        {name}: {received} received, {lost} skipped");
    }
}

/// Ring `name`'s header, read directly from its segment (`--ring-dir`, `--ring-owner`).
fn print_ring_header(args: &StatusArgs, name: &str) -> anyhow::Result<()> {
    let dir = args
        .ring_dir
        .clone()
        .unwrap_or_else(crate::output::ring::location::default_dir);
    let owner = match &args.ring_owner {
        Some(o) => Some(sys::user_id(o)?),
        None => crate::output::ring::location::owner_from_env()?,
    };
    let r = crate::output::ring::RingReader::open(&RingLocation::new(dir, name)?, owner)?;
    let g = r.geometry();
    let alive = r.producer_alive();
    let state = match (r.state(), alive) {
        (1, true) => "live",
        (1, false) => "stale (its producer is gone)",
        (2, _) => "closed",
        (3, _) => "replaced",
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
    Ok(())
}
