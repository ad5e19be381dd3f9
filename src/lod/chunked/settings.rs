//! GPU chunked LOD's settings (config `[method] name = "chunked"`, `docs/chunked.md`).

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::lod::sweep::Sweep;
pub use crate::lod::udlod::settings::LodMetric;

/// How the quadtree is walked on the GPU (Hedberg's two selection variants).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Traversal {
    /// The tree walked level by level from the root depth every frame: one compute dispatch
    /// per level over ping-pong chunk lists.
    #[default]
    Naive,
    /// The tree kept as a concurrent binary tree (a bit field with a sum-reduction tree) that
    /// persists across frames: per frame a dispatch kernel, one split/merge step per leaf and
    /// the sum reduction. Converges to the naive selection over frames.
    Cbt,
}

impl Traversal {
    pub fn name(self) -> &'static str {
        match self {
            Traversal::Naive => "naive",
            Traversal::Cbt => "cbt",
        }
    }
}

/// How the selected chunks are drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ChunkDraw {
    /// One chunk mesh instanced per selected chunk through one indexed indirect draw.
    #[default]
    Instanced,
    /// Task + mesh shaders (GLSL, `shaders/glsl/chunked.task|mesh`): one task workgroup per
    /// listed chunk, one mesh workgroup per block of it, through one indirect mesh-task draw.
    /// Needs `VK_EXT_mesh_shader` with `taskShader` and `meshShader`.
    Mesh,
}

impl ChunkDraw {
    pub fn name(self) -> &'static str {
        match self {
            ChunkDraw::Instanced => "instanced",
            ChunkDraw::Mesh => "mesh",
        }
    }
}

#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct ChunkedSettings {
    pub traversal: Traversal,
    pub draw: ChunkDraw,
    /// Quads per chunk side (a power of two, 2..=64). Edge patching covers neighbours up to
    /// log2(chunk_quads) levels apart.
    pub chunk_quads: u32,
    /// A chunk splits while its geometric error projected at its bounding sphere's distance
    /// exceeds this many pixels (Hedberg used 4).
    pub error_px: f64,
    /// Levels below the root that are always split: the walk starts with the 4^root_depth
    /// chunks of that level (Hedberg: 2).
    pub root_depth: u32,
    /// Most levels below the root the tree may reach (the tree depth; larger than the data's
    /// levels: down to full resolution).
    pub max_depth: u32,
    /// Capacity of the render list and of each traversal list (chunks per frame and view).
    pub max_chunks: u32,
    /// Frustum culling with the chunks' bounding spheres.
    pub cull: bool,
    /// Edge patching against a coarser neighbour through the LOD map (off: an ablation that
    /// shows the cracks it closes; tests use it as the watertightness check's control).
    pub stitch: bool,
    /// The LOD metric on a native non-square grid on the earth (docs/chunked.md, "On the
    /// earth"): `axis` measures split distances to the chunk's box with each axis's own
    /// smallest spacing; `smallest` keeps the bounding sphere in the grid's one smallest
    /// spacing (the ablation, what chunked LOD did before). Square grids: the sphere either way.
    pub lod_metric: LodMetric,
}

impl Default for ChunkedSettings {
    fn default() -> Self {
        ChunkedSettings {
            traversal: Traversal::Naive,
            draw: ChunkDraw::Instanced,
            chunk_quads: 16,
            error_px: 4.0,
            root_depth: 2,
            max_depth: 32,
            max_chunks: 16384,
            cull: true,
            stitch: true,
            lod_metric: LodMetric::Axis,
        }
    }
}

impl ChunkedSettings {
    /// What `vkterrain eval --sweep KEY=...` varies for chunked LOD.
    pub const SWEEP: &[Sweep<Self>] = &[
        Sweep {
            key: "error_px",
            help: "screen-space error threshold (px)",
            apply: |s, v| s.error_px = v,
        },
        Sweep {
            key: "chunk_quads",
            help: "quads per chunk side",
            apply: |s, v| s.chunk_quads = v as u32,
        },
        Sweep {
            key: "max_depth",
            help: "most levels below the root (tree depth)",
            apply: |s, v| s.max_depth = v as u32,
        },
        Sweep {
            key: "root_depth",
            help: "levels below the root always split",
            apply: |s, v| s.root_depth = v as u32,
        },
    ];

    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::invalid("chunked settings", m));
        if !(2..=64).contains(&self.chunk_quads) || !self.chunk_quads.is_power_of_two() {
            return bad(format!(
                "chunk_quads {} must be a power of two within 2..=64",
                self.chunk_quads
            ));
        }
        if !(self.error_px.is_finite() && (0.05..=1000.0).contains(&self.error_px)) {
            return bad(format!(
                "error_px {} must be within 0.05..=1000 pixels",
                self.error_px
            ));
        }
        if self.root_depth > 6 {
            return bad(format!("root_depth {} must be at most 6", self.root_depth));
        }
        if !(1..=32).contains(&self.max_depth) {
            return bad(format!(
                "max_depth {} must be within 1..=32",
                self.max_depth
            ));
        }
        // The LOD map pass dispatches one workgroup per listed chunk.
        if !(16..=65535).contains(&self.max_chunks) {
            return bad(format!(
                "max_chunks {} must be within 16..=65535",
                self.max_chunks
            ));
        }
        Ok(())
    }
}

impl From<ChunkedSettings> for crate::lod::MethodConfig {
    fn from(s: ChunkedSettings) -> Self {
        crate::lod::MethodConfig::Chunked(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lod::MethodConfig;

    #[test]
    fn config_section_selects_chunked_with_its_settings() {
        let m: MethodConfig = toml::from_str(
            "name = \"chunked\"\ntraversal = \"cbt\"\ndraw = \"mesh\"\nerror_px = 2.0",
        )
        .unwrap();
        let MethodConfig::Chunked(s) = &m else {
            panic!("{m:?}")
        };
        assert_eq!(s.traversal, Traversal::Cbt);
        assert_eq!(s.draw, ChunkDraw::Mesh);
        assert_eq!(s.error_px, 2.0);
        assert_eq!(s.chunk_quads, ChunkedSettings::default().chunk_quads);
        // A stray key, an unknown variant and a bad value are errors, not ignored.
        assert!(toml::from_str::<MethodConfig>("name = \"chunked\"\ntau_px = 2.0").is_err());
        assert!(toml::from_str::<MethodConfig>("name = \"chunked\"\ntraversal = \"x\"").is_err());
        let bad = ChunkedSettings {
            chunk_quads: 12,
            ..Default::default()
        };
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("chunk_quads"), "{e}");
        let mut m = MethodConfig::from(ChunkedSettings::default());
        m.apply_sweep("error_px", 8.0).unwrap();
        let MethodConfig::Chunked(s) = m else {
            panic!()
        };
        assert_eq!(s.error_px, 8.0);
    }
}
