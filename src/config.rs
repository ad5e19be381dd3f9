//! Configuration (`config/*.toml`): device, render size, data set, LOD method, scenario, output.
//!
//! Every field has a default, so an empty file is a valid configuration. Relative paths in a
//! config file are relative to the file's directory. Values are checked in [`Config::validate`]
//! before anything is created, so bad input never leaves partial output behind.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::error::{Error, Result};

/// Largest render target side accepted (the device limit is checked too).
pub const MAX_RESOLUTION: u32 = 16384;

#[derive(Clone, Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    pub device: DeviceConfig,
    pub render: RenderConfig,
    pub dataset: DatasetConfig,
    pub method: MethodConfig,
    pub scenario: ScenarioConfig,
    pub lod: crate::lod::LodSettings,
    /// Heights through the chunked clipmap (`dataset.kind = "tiles"` only).
    pub clipmap: crate::clipmap::ClipmapSettings,
    pub output: OutputConfig,
    pub ring: RingConfig,
    pub service: ServiceConfig,
    /// Frames, control and status over Zenoh (`serve`).
    pub zenoh: crate::service::ZenohSettings,
    /// Directory relative paths are resolved against (the config file's directory).
    #[serde(skip)]
    pub base_dir: PathBuf,
}

#[derive(Clone, Debug, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DeviceConfig {
    /// Device override: index or name substring (`VKTERRAIN_DEVICE` wins over this).
    pub select: Option<String>,
    /// Enable the Khronos validation layers (with synchronization validation).
    pub validation: bool,
    /// Use render passes + classic barriers even on Vulkan 1.3 devices.
    pub force_legacy: bool,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RenderConfig {
    pub width: u32,
    pub height: u32,
    pub frames_in_flight: u32,
    /// Also read back the depth buffer (tests and evaluation).
    pub readback_depth: bool,
    /// Linear-space RGB of the sky (clear colour).
    pub sky: [f32; 3],
    /// Direction *towards* the sun: azimuth clockwise from north and elevation, degrees.
    pub sun_azimuth_deg: f32,
    pub sun_elevation_deg: f32,
    /// Further cameras drawn into the same frame, side by side right of the main one (each
    /// view gets `width / views` columns); they share the clipmap's atlas.
    pub extra_views: Vec<crate::scene::ViewOffset>,
}

impl Default for RenderConfig {
    fn default() -> Self {
        RenderConfig {
            width: 1280,
            height: 720,
            frames_in_flight: 2,
            readback_depth: false,
            sky: [0.45, 0.62, 0.85],
            sun_azimuth_deg: 135.0,
            sun_elevation_deg: 35.0,
            extra_views: Vec::new(),
        }
    }
}

#[derive(Clone, Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DatasetConfig {
    /// `procedural` (generated in code, the embedded default) or `png16` (a 16-bit PNG).
    pub kind: String,
    pub size: u32,
    pub seed: u64,
    /// Sample spacing in metres.
    pub spacing: f64,
    /// For `png16`: the height PNG, metres per unit, and an optional albedo image.
    pub path: Option<PathBuf>,
    pub vertical_scale: f64,
    pub albedo: Option<PathBuf>,
    /// For `tiles` (`path` = a `vkterrain preprocess` output directory): the level to load;
    /// none: the finest level that fits.
    pub lod: Option<u32>,
}

impl Default for DatasetConfig {
    fn default() -> Self {
        DatasetConfig {
            kind: "procedural".into(),
            size: 1025,
            seed: 1,
            spacing: 30.0,
            path: None,
            vertical_scale: 1.0,
            albedo: None,
            lod: None,
        }
    }
}

#[derive(Clone, Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MethodConfig {
    /// LOD method: `brute` (every sample a vertex), `udlod` or `pgm`.
    pub name: String,
}

impl Default for MethodConfig {
    fn default() -> Self {
        MethodConfig {
            name: "brute".into(),
        }
    }
}

#[derive(Clone, Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
#[derive(Default)]
pub struct ScenarioConfig {
    /// Scenario file; none: the built-in default flight (`config/scenarios/default.toml`,
    /// compiled into the binary).
    pub path: Option<PathBuf>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OutputConfig {
    pub dir: PathBuf,
    /// Frame indices written as PNG (negative: counted from the end, -1 = last frame).
    pub png_frames: Vec<i64>,
}

impl Default for OutputConfig {
    fn default() -> Self {
        OutputConfig {
            dir: PathBuf::from("out"),
            png_frames: vec![0, -1],
        }
    }
}

/// The shared-memory ring `vkterrain serve` publishes into (`docs/ring.md`).
#[derive(Clone, Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RingConfig {
    /// Ring name: the segment is `<dir>/<name>`, 1..=200 characters from `[A-Za-z0-9._-]`.
    pub name: String,
    /// Directory of the rings, writable by the service only (default `$VKTERRAIN_RING_DIR`, else
    /// `/run/vkterrain`; docs/ring.md "Threat model").
    pub dir: Option<PathBuf>,
    /// Let the GPU write frames straight into the ring slots where the device can
    /// (`VK_EXT_external_memory_host`); else every frame is copied.
    pub zero_copy: bool,
    /// Slots in the ring (2..=64): how far a consumer may fall behind before it skips frames.
    pub slots: u32,
    /// Group allowed to read the ring (mode 0640); none: owner only (mode 0600).
    pub group: Option<String>,
    /// Leave the segment (marked closed) in place after shutdown.
    pub keep_segment: bool,
}

impl Default for RingConfig {
    fn default() -> Self {
        RingConfig {
            name: "vkterrain".into(),
            dir: None,
            zero_copy: true,
            slots: 4,
            group: None,
            keep_segment: false,
        }
    }
}

/// `vkterrain serve`: control channel, status file, pacing.
#[derive(Clone, Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServiceConfig {
    /// Unix datagram socket for live camera control (JSON messages); none: scripted only.
    pub control: Option<PathBuf>,
    /// JSON status file, rewritten atomically every `status_interval_s`.
    pub status_file: Option<PathBuf>,
    pub status_interval_s: f64,
    /// Frame-rate cap (0: as fast as the device renders).
    pub max_fps: f64,
}

impl Default for ServiceConfig {
    fn default() -> Self {
        ServiceConfig {
            control: None,
            status_file: None,
            status_interval_s: 1.0,
            max_fps: 0.0,
        }
    }
}

impl Default for Config {
    fn default() -> Self {
        Config {
            device: Default::default(),
            render: Default::default(),
            dataset: Default::default(),
            method: Default::default(),
            scenario: Default::default(),
            lod: Default::default(),
            clipmap: Default::default(),
            output: Default::default(),
            ring: Default::default(),
            service: Default::default(),
            zenoh: Default::default(),
            // No config file: relative paths are relative to the working directory.
            base_dir: PathBuf::new(),
        }
    }
}

/// Formats a TOML error as `path:line: message`.
pub fn toml_error(path: &Path, text: &str, e: &toml::de::Error) -> Error {
    let line = e
        .span()
        .map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1);
    let path = match line {
        Some(l) => PathBuf::from(format!("{}:{l}", path.display())),
        None => path.to_path_buf(),
    };
    Error::Config {
        path,
        message: e.message().trim().replace('\n', " "),
    }
}

impl Config {
    /// Reads a config file (no file: the built-in defaults).
    pub fn load(path: Option<&Path>) -> Result<Self> {
        let Some(path) = path else {
            return Ok(Config::default());
        };
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let mut config: Config = toml::from_str(&text).map_err(|e| toml_error(path, &text, &e))?;
        config.base_dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        config.validate().map_err(|e| Error::Config {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        Ok(config)
    }

    /// A path from the config, resolved against the config file's directory.
    pub fn resolve(&self, p: &Path) -> PathBuf {
        if p.is_absolute() {
            p.to_path_buf()
        } else {
            self.base_dir.join(p)
        }
    }

    /// Checks values that serde cannot (ranges, names).
    pub fn validate(&self) -> Result<()> {
        let r = &self.render;
        if r.width == 0 || r.height == 0 || r.width > MAX_RESOLUTION || r.height > MAX_RESOLUTION {
            return Err(Error::invalid(
                "resolution",
                format!(
                    "{}x{} is outside 1..={MAX_RESOLUTION} per side",
                    r.width, r.height
                ),
            ));
        }
        if !(1..=8).contains(&r.frames_in_flight) {
            return Err(Error::invalid(
                "frames_in_flight",
                format!("{} is outside 1..=8", r.frames_in_flight),
            ));
        }
        if r.extra_views.len() > crate::render::MAX_VIEWS - 1 {
            return Err(Error::invalid(
                "render.extra_views",
                format!(
                    "{} extra views; at most {} views per frame",
                    r.extra_views.len(),
                    crate::render::MAX_VIEWS
                ),
            ));
        }
        if (r.extra_views.len() as u32 + 1) > r.width {
            return Err(Error::invalid(
                "render.extra_views",
                format!(
                    "{} views do not fit in {} columns",
                    r.extra_views.len() + 1,
                    r.width
                ),
            ));
        }
        for v in &r.extra_views {
            v.validate()?;
        }
        if r.sky
            .iter()
            .chain([&r.sun_azimuth_deg, &r.sun_elevation_deg])
            .any(|v| !v.is_finite())
        {
            return Err(Error::invalid(
                "render",
                "sky colour and sun angles must be finite",
            ));
        }
        match self.dataset.kind.as_str() {
            "procedural" => {
                if !(2..=crate::dataset::MAX_SIDE).contains(&self.dataset.size) {
                    return Err(Error::invalid(
                        "dataset.size",
                        format!(
                            "{} is outside 2..={}",
                            self.dataset.size,
                            crate::dataset::MAX_SIDE
                        ),
                    ));
                }
            }
            "png16" | "tiles" => {
                if self.dataset.path.is_none() {
                    return Err(Error::invalid(
                        "dataset.path",
                        format!("kind = {:?} needs a path", self.dataset.kind),
                    ));
                }
            }
            other => {
                return Err(Error::invalid(
                    "dataset.kind",
                    format!("unknown kind {other:?} (expected procedural, png16, tiles)"),
                ));
            }
        }
        if !(self.dataset.spacing.is_finite() && self.dataset.spacing > 0.0) {
            return Err(Error::invalid(
                "dataset.spacing",
                format!("{} m must be positive", self.dataset.spacing),
            ));
        }
        if !(self.dataset.vertical_scale.is_finite() && self.dataset.vertical_scale > 0.0) {
            return Err(Error::invalid(
                "dataset.vertical_scale",
                format!("{} must be positive", self.dataset.vertical_scale),
            ));
        }
        crate::lod::MethodKind::parse(&self.method.name)?;
        self.lod.validate()?;
        crate::output::ring::validate_name(&self.ring.name)?;
        if !(2..=64).contains(&self.ring.slots) {
            return Err(Error::invalid(
                "ring.slots",
                format!("{} is outside 2..=64", self.ring.slots),
            ));
        }
        self.zenoh.validate()?;
        let s = &self.service;
        if !(s.status_interval_s.is_finite() && (0.05..=3600.0).contains(&s.status_interval_s)) {
            return Err(Error::invalid(
                "service.status_interval_s",
                format!("{} is outside 0.05..=3600", s.status_interval_s),
            ));
        }
        if !(s.max_fps.is_finite() && (0.0..=10000.0).contains(&s.max_fps)) {
            return Err(Error::invalid(
                "service.max_fps",
                format!("{} is outside 0..=10000", s.max_fps),
            ));
        }
        self.clipmap.validate()?;
        if self.clipmap.enabled && self.dataset.kind != "tiles" {
            return Err(Error::invalid(
                "clipmap.enabled",
                format!(
                    "needs dataset.kind = \"tiles\" (a vkterrain preprocess data set), not {:?}",
                    self.dataset.kind
                ),
            ));
        }
        if self.clipmap.enabled && self.dataset.lod.is_some_and(|l| l != 0) {
            return Err(Error::invalid(
                "clipmap.enabled",
                "the clipmap streams every level; dataset.lod must be 0 or absent",
            ));
        }
        if self.clipmap.enabled && self.method.name == "pgm" {
            return Err(Error::invalid(
                "clipmap.enabled",
                "method pgm needs the whole height map in memory (its own height texture); use udlod or brute with the clipmap, or set clipmap.enabled = false",
            ));
        }
        Ok(())
    }
}
