//! `[ring]`: the shared-memory ring `vkterrain serve` publishes into (`docs/ring.md`).

use std::path::PathBuf;

use serde::Deserialize;

use crate::error::{Error, Result};

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

impl RingConfig {
    pub fn validate(&self) -> Result<()> {
        super::validate_name(&self.name)?;
        if !(2..=64).contains(&self.slots) {
            return Err(Error::invalid(
                "ring.slots",
                format!("{} is outside 2..=64", self.slots),
            ));
        }
        Ok(())
    }
}
