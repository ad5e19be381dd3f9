//! GeoMipMapping's settings (config `[method] name = "geomipmap"`, `docs/geomipmap.md`).

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::lod::sweep::Sweep;

#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct GeomipmapSettings {
    /// A block is drawn at full resolution while its nearest point is closer than
    /// `distance_factor` block widths; every doubling of the distance beyond that drops one
    /// level. Larger: finer.
    pub distance_factor: f64,
    /// Frustum culling of blocks on the CPU (per-block height bounds).
    pub cull: bool,
    /// Which box culling tests on the earth (the flat world has one box).
    pub cull_box: CullBox,
    /// Border permutations against a coarser neighbour (off: an ablation showing the
    /// T-junction cracks they close; tests use it as the watertightness check's control).
    pub stitch: bool,
}

/// The box a block is culled with on the earth (config `cull_box`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum CullBox {
    /// The curved box every method culls with on the earth (`Lattice::rect_box`).
    Lattice,
    /// The grid-frame box (`x = col * spacing`, `y = row * spacing`) tested against the
    /// world-frame camera: an ablation, what GeoMipMapping did before, wrong on the earth
    /// (the grid frame bends away from the world frame); tests use it as a control.
    Grid,
}

impl Default for GeomipmapSettings {
    fn default() -> Self {
        GeomipmapSettings {
            distance_factor: 2.0,
            cull: true,
            cull_box: CullBox::Lattice,
            stitch: true,
        }
    }
}

impl GeomipmapSettings {
    /// What `vkterrain eval --sweep KEY=...` varies for GeoMipMapping.
    pub const SWEEP: &[Sweep<Self>] = &[Sweep {
        key: "distance_factor",
        help: "block widths within which a block stays at full resolution",
        apply: |s, v| s.distance_factor = v,
    }];

    pub fn validate(&self) -> Result<()> {
        if !(self.distance_factor.is_finite() && (0.01..=1000.0).contains(&self.distance_factor)) {
            return Err(Error::invalid(
                "geomipmap settings",
                format!(
                    "distance_factor {} must be within 0.01..=1000",
                    self.distance_factor
                ),
            ));
        }
        Ok(())
    }
}

impl From<GeomipmapSettings> for crate::lod::MethodConfig {
    fn from(s: GeomipmapSettings) -> Self {
        crate::lod::MethodConfig::Geomipmap(s)
    }
}
