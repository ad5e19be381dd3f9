//! `[service]` and `[zenoh]`: what `vkterrain serve` does besides rendering.

use std::path::PathBuf;

use serde::Deserialize;

use crate::error::{Error, Result};

/// `[zenoh]`: frames, control and status over Zenoh (`docs/zenoh.md`).
#[derive(Clone, Debug, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ZenohSettings {
    /// Publish over Zenoh (`serve --zenoh`).
    pub enabled: bool,
    /// First chunks of every key expression: `<prefix>/<ring>/frame|control|status`.
    pub prefix: String,
    /// Zenoh session mode: "peer" or "client".
    pub mode: String,
    /// Endpoints to listen on, e.g. "tcp/0.0.0.0:7447".
    pub listen: Vec<String>,
    /// Endpoints to connect to, e.g. "tcp/192.168.1.20:7447".
    pub connect: Vec<String>,
    /// Find peers by UDP multicast (off: only the configured endpoints).
    pub multicast_scouting: bool,
    /// Zenoh shared memory for subscribers on the same machine.
    pub shared_memory: bool,
    /// Frames waiting for the network at most; more are dropped (counted), never waited for.
    pub queue: usize,
}

impl Default for ZenohSettings {
    fn default() -> Self {
        ZenohSettings {
            enabled: false,
            prefix: "vkterrain".into(),
            mode: "peer".into(),
            listen: Vec::new(),
            connect: Vec::new(),
            multicast_scouting: false,
            shared_memory: true,
            queue: 2,
        }
    }
}

impl ZenohSettings {
    pub fn validate(&self) -> Result<()> {
        let ok_chunk = |c: &str| {
            !c.is_empty()
                && c.bytes()
                    .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'_' | b'-' | b'.'))
        };
        if !self.prefix.split('/').all(ok_chunk) {
            return Err(Error::invalid(
                "zenoh.prefix",
                format!(
                    "{:?}: use chunks of [A-Za-z0-9._-] separated by '/'",
                    self.prefix
                ),
            ));
        }
        if !matches!(self.mode.as_str(), "peer" | "client") {
            return Err(Error::invalid(
                "zenoh.mode",
                format!("{:?} is not \"peer\" or \"client\"", self.mode),
            ));
        }
        if !(1..=64).contains(&self.queue) {
            return Err(Error::invalid(
                "zenoh.queue",
                format!("{} is outside 1..=64", self.queue),
            ));
        }
        Ok(())
    }
}

/// `[service]`: control channel, status file, pacing.
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

impl ServiceConfig {
    pub fn validate(&self) -> Result<()> {
        if !(self.status_interval_s.is_finite()
            && (0.05..=3600.0).contains(&self.status_interval_s))
        {
            return Err(Error::invalid(
                "service.status_interval_s",
                format!("{} is outside 0.05..=3600", self.status_interval_s),
            ));
        }
        if !(self.max_fps.is_finite() && (0.0..=10000.0).contains(&self.max_fps)) {
            return Err(Error::invalid(
                "service.max_fps",
                format!("{} is outside 0..=10000", self.max_fps),
            ));
        }
        Ok(())
    }
}
