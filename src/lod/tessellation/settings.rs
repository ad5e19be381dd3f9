//! Hardware tessellation's settings (config `[method] name = "tessellation"`,
//! `docs/tessellation.md`).

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::lod::sweep::Sweep;

/// How the tessellator spaces the vertices of an edge (the evaluation stage's spacing mode).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Spacing {
    /// Levels rounded up to whole numbers: vertices jump when a level changes (pops).
    Equal,
    /// Fractional levels, odd segment counts: new vertices grow out of existing ones.
    #[default]
    FractionalOdd,
    /// Fractional levels, even segment counts.
    FractionalEven,
}

impl Spacing {
    pub fn name(self) -> &'static str {
        match self {
            Spacing::Equal => "equal",
            Spacing::FractionalOdd => "fractional_odd",
            Spacing::FractionalEven => "fractional_even",
        }
    }
}

/// Where an outer level's view depth comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EdgeLevels {
    /// The edge's own midpoint (Fischer's rule): the two patches on an edge agree, no cracks.
    #[default]
    Edge,
    /// The patch's centroid, for all three edges: an ablation that shows the T-junction
    /// cracks the edge rule avoids (tests use it as the watertightness check's control).
    Patch,
}

/// The surface the evaluation stage displaces onto.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Surface {
    /// The height map's bilinear field (Fischer: the height map sampled at the vertex).
    #[default]
    Bilinear,
    /// Brute force's triangles (the exact surface eval measures against); not through the
    /// clipmap, which falls back to the bilinear field.
    Mesh,
}

#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct TessellationSettings {
    /// Height samples per side of a patch quad (two triangle patches); at the highest level
    /// (64) an edge of 64 samples gets one vertex per sample.
    pub patch_samples: u32,
    /// Target on-screen length of a generated edge in pixels (Fischer's
    /// `tessellatedEdgeSize`, in true pixels: see docs/tessellation.md).
    pub edge_px: f64,
    /// Multiplies every level (Fischer's `tessellationFactor`).
    pub factor: f64,
    /// Vertex spacing of the tessellator.
    pub spacing: Spacing,
    /// Frustum culling of patches in the control stage (per-patch height bounds).
    pub cull: bool,
    /// Edge levels from each edge's endpoints (default) or, as an ablation, the patch centroid.
    pub edge_levels: EdgeLevels,
    /// The displaced surface: bilinear (default) or brute force's triangles.
    pub surface: Surface,
}

impl Default for TessellationSettings {
    fn default() -> Self {
        TessellationSettings {
            patch_samples: 64,
            edge_px: 8.0,
            factor: 1.0,
            spacing: Spacing::FractionalOdd,
            cull: true,
            edge_levels: EdgeLevels::Edge,
            surface: Surface::Bilinear,
        }
    }
}

/// Highest tessellation level Vulkan guarantees (`maxTessellationGenerationLevel` >= 64).
pub const MAX_LEVEL: f32 = 64.0;

impl TessellationSettings {
    /// What `vkterrain eval --sweep KEY=...` varies for tessellation.
    pub const SWEEP: &[Sweep<Self>] = &[
        Sweep {
            key: "edge_px",
            help: "target on-screen edge length (px)",
            apply: |s, v| s.edge_px = v,
        },
        Sweep {
            key: "factor",
            help: "tessellation factor (multiplies every level)",
            apply: |s, v| s.factor = v,
        },
        Sweep {
            key: "patch_samples",
            help: "samples per patch side",
            apply: |s, v| s.patch_samples = v as u32,
        },
    ];

    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::invalid("tessellation settings", m));
        if !(1..=1024).contains(&self.patch_samples) {
            return bad(format!(
                "patch_samples {} must be within 1..=1024",
                self.patch_samples
            ));
        }
        if !(self.edge_px.is_finite() && (0.25..=10_000.0).contains(&self.edge_px)) {
            return bad(format!(
                "edge_px {} must be within 0.25..=10000 pixels",
                self.edge_px
            ));
        }
        if !(self.factor.is_finite() && self.factor > 0.0 && self.factor <= 1000.0) {
            return bad(format!("factor {} must be within (0, 1000]", self.factor));
        }
        Ok(())
    }
}

impl From<TessellationSettings> for crate::lod::MethodConfig {
    fn from(s: TessellationSettings) -> Self {
        crate::lod::MethodConfig::Tessellation(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lod::MethodConfig;

    #[test]
    fn config_section_selects_tessellation_with_its_settings() {
        let m: MethodConfig = toml::from_str(
            "name = \"tessellation\"\nedge_px = 4.0\nspacing = \"fractional_even\"\nedge_levels = \"patch\"\nsurface = \"mesh\"",
        )
        .unwrap();
        let MethodConfig::Tessellation(s) = &m else {
            panic!("{m:?}")
        };
        assert_eq!(s.edge_px, 4.0);
        assert_eq!(s.spacing, Spacing::FractionalEven);
        assert_eq!(s.edge_levels, EdgeLevels::Patch);
        assert_eq!(s.surface, Surface::Mesh);
        assert_eq!(
            s.patch_samples,
            TessellationSettings::default().patch_samples
        );
        // A stray key and a bad value are errors, not ignored.
        assert!(toml::from_str::<MethodConfig>("name = \"tessellation\"\ntau_px = 2.0").is_err());
        let bad = TessellationSettings {
            edge_px: 0.0,
            ..Default::default()
        };
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("edge_px"), "{e}");
        // The sweep key sets the edge size.
        let mut m = MethodConfig::from(TessellationSettings::default());
        m.apply_sweep("edge_px", 2.5).unwrap();
        let MethodConfig::Tessellation(s) = m else {
            panic!()
        };
        assert_eq!(s.edge_px, 2.5);
    }
}
