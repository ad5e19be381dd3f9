//! What `vkterrain serve` offers besides the ring: camera control (a Unix datagram socket and,
//! with the `zenoh` feature, Zenoh), with one validation and one set of counters for both, and
//! frames, metadata and status over Zenoh (`docs/zenoh.md`).

pub mod control;
#[cfg(feature = "zenoh")]
pub mod zenoh;

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
