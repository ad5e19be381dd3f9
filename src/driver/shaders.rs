//! SPIR-V compiled from `shaders/*.wgsl` (and `shaders/glsl/`) by `build.rs`, the choice of the
//! frame block's variant per device, and shader-module creation.

use ash::vk;

use super::Gpu;
use super::device::DeviceInfo;
use crate::error::{Error, Result, VkResultExt};

include!(concat!(env!("OUT_DIR"), "/shaders.rs"));

/// Environment variable that overrides [`FrameBlock::for_device`]: `uniform` or `storage`.
pub const FRAME_BLOCK_ENV: &str = "VKTERRAIN_FRAME_BLOCK";

/// How the shaders read the frame's block (`frame`, set 0 binding 0,
/// `shaders/include/terrain_common.wgsl`). Every shader that reads it is built both ways.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameBlock {
    /// A uniform buffer: what NVIDIA's driver reads fastest (a storage buffer cost UDLOD 3-5 %
    /// of its GPU time at 1080p on an H100 and an H200).
    Uniform,
    /// A read-only storage buffer: Mesa's lavapipe before 24 inlines uniform values that steer
    /// branches and rebuilds the shaders whenever their descriptors are bound again, every
    /// frame (docs/architecture.md, "Uniform buffers on Mesa 22.3").
    Storage,
}

impl FrameBlock {
    /// The variant for a device: [`FrameBlock::Storage`] on lavapipe (llvmpipe) of a Mesa
    /// release before 24, [`FrameBlock::Uniform`] everywhere else (Mesa 25's lavapipe draws
    /// alike with both; measured, docs/architecture.md).
    pub fn for_device(info: &DeviceInfo) -> FrameBlock {
        Self::for_driver(info.driver_id, &info.driver_info)
    }

    /// [`FrameBlock::for_device`] from the driver's ID and `driverInfo` (`Mesa 22.3.6 (LLVM
    /// 15.0.6)` on lavapipe; without a Mesa release in it, a uniform buffer).
    pub fn for_driver(id: vk::DriverId, driver_info: &str) -> FrameBlock {
        match mesa_major(driver_info) {
            Some(major) if id == vk::DriverId::MESA_LLVMPIPE && major < 24 => FrameBlock::Storage,
            _ => FrameBlock::Uniform,
        }
    }

    /// `uniform` or `storage` (as [`FRAME_BLOCK_ENV`] takes it).
    pub fn parse(name: &str) -> Result<FrameBlock> {
        match name.trim().to_ascii_lowercase().as_str() {
            "uniform" => Ok(FrameBlock::Uniform),
            "storage" => Ok(FrameBlock::Storage),
            other => Err(Error::invalid(
                FRAME_BLOCK_ENV,
                format!("unknown frame block {other:?} (uniform or storage)"),
            )),
        }
    }

    pub const fn descriptor_type(self) -> vk::DescriptorType {
        match self {
            FrameBlock::Uniform => vk::DescriptorType::UNIFORM_BUFFER,
            FrameBlock::Storage => vk::DescriptorType::STORAGE_BUFFER,
        }
    }

    pub fn buffer_usage(self) -> vk::BufferUsageFlags {
        match self {
            FrameBlock::Uniform => vk::BufferUsageFlags::UNIFORM_BUFFER,
            FrameBlock::Storage => vk::BufferUsageFlags::STORAGE_BUFFER,
        }
    }
}

/// The major release in a Mesa driver's `driverInfo` (`Mesa 22.3.6 (LLVM 15.0.6)` -> 22).
fn mesa_major(driver_info: &str) -> Option<u32> {
    let mut words = driver_info.split_whitespace();
    words.find(|w| *w == "Mesa")?;
    words.next()?.split('.').next()?.parse().ok()
}

/// One shader's SPIR-V as `build.rs` embeds it: as written, and for a shader that reads the
/// frame's block, with that block a read-only storage buffer.
#[derive(Clone, Copy, Debug)]
pub struct Spirv {
    pub frame_uniform: &'static [u8],
    pub frame_storage: Option<&'static [u8]>,
}

impl Spirv {
    /// The bytes for a device whose frame block is `block` (the only variant of a shader that
    /// does not read the block).
    pub fn bytes(self, block: FrameBlock) -> &'static [u8] {
        match (block, self.frame_storage) {
            (FrameBlock::Storage, Some(storage)) => storage,
            _ => self.frame_uniform,
        }
    }
}

/// The world a terrain shader is built for (`EARTH_WORLD` in
/// `shaders/include/terrain_common.wgsl`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShaderWorld {
    /// The grid on the tangent plane: positions from the camera's sample cell.
    Flat,
    /// The samples where they lie on the earth: positions through the geolocation lattice.
    Earth,
}

/// Where a terrain shader reads heights, normals and albedo (`CLIPMAP_HEIGHTS`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShaderHeights {
    /// The single height, normal and albedo textures (bindings 1-3).
    Texture,
    /// The chunked clipmap's atlas through the view's quadtree (bindings 5-8).
    Clipmap,
}

/// Which build of a terrain shader draws a terrain: every shader that includes
/// `terrain_common.wgsl` (or, in GLSL, `terrain_common.glsl`) is compiled once per world and
/// source of heights, each deciding those branches at build time, so no driver runs the other
/// paths (lavapipe before Mesa 24 runs both sides of a branch on a storage buffer's value:
/// docs/architecture.md, "Shaders per terrain").
/// `frame::TerrainGpu::variant` gives the terrain's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TerrainVariant {
    pub world: ShaderWorld,
    pub heights: ShaderHeights,
}

impl TerrainVariant {
    /// The variant for a terrain drawn through a geolocation lattice or not (`earth`), from the
    /// clipmap or not (`clipmap`).
    pub const fn new(earth: bool, clipmap: bool) -> TerrainVariant {
        TerrainVariant {
            world: if earth {
                ShaderWorld::Earth
            } else {
                ShaderWorld::Flat
            },
            heights: if clipmap {
                ShaderHeights::Clipmap
            } else {
                ShaderHeights::Texture
            },
        }
    }
}

/// A terrain shader's SPIR-V per [`TerrainVariant`] (`build.rs` compiles each with its
/// overrides set, or for GLSL its `#define`s).
#[derive(Clone, Copy, Debug)]
pub struct TerrainSpirv {
    pub flat_texture: Spirv,
    pub flat_clipmap: Spirv,
    pub earth_texture: Spirv,
    pub earth_clipmap: Spirv,
}

impl TerrainSpirv {
    /// The build for `variant`.
    pub const fn variant(self, variant: TerrainVariant) -> Spirv {
        match (variant.world, variant.heights) {
            (ShaderWorld::Flat, ShaderHeights::Texture) => self.flat_texture,
            (ShaderWorld::Flat, ShaderHeights::Clipmap) => self.flat_clipmap,
            (ShaderWorld::Earth, ShaderHeights::Texture) => self.earth_texture,
            (ShaderWorld::Earth, ShaderHeights::Clipmap) => self.earth_clipmap,
        }
    }
}

/// Creates a shader module from the variant of `spv` for `gpu`'s frame block.
pub fn module(gpu: &Gpu, spv: Spirv) -> Result<vk::ShaderModule> {
    let bytes = spv.bytes(gpu.frame_block);
    let words = ash::util::read_spv(&mut std::io::Cursor::new(bytes))
        .map_err(|e| Error::invalid("SPIR-V", e.to_string()))?;
    unsafe {
        gpu.device
            .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)
    }
    .vk("vkCreateShaderModule")
}

#[cfg(test)]
mod tests {
    use super::*;

    const VARIANTS: [TerrainVariant; 4] = [
        TerrainVariant::new(false, false),
        TerrainVariant::new(false, true),
        TerrainVariant::new(true, false),
        TerrainVariant::new(true, true),
    ];

    #[test]
    fn every_shader_that_reads_the_frame_block_has_a_storage_variant() {
        // The probe and the methods' shaders read `frame`; the evaluator's metrics do not.
        let terrain = [
            BRUTE_SPV,
            UDLOD_SPV,
            UDLOD_TILING_SPV,
            TESS_EQUAL_TESE_SPV,
            TERRAIN_PROBE_COMP_SPV,
        ];
        for spv in terrain.iter().flat_map(|t| VARIANTS.map(|v| t.variant(v))) {
            let storage = spv.frame_storage.expect("a storage variant");
            assert_ne!(storage, spv.frame_uniform);
            assert_eq!(spv.bytes(FrameBlock::Storage), storage);
            assert_eq!(spv.bytes(FrameBlock::Uniform), spv.frame_uniform);
        }
        assert!(EVAL_METRICS_SPV.frame_storage.is_none());
        assert_eq!(
            EVAL_METRICS_SPV.bytes(FrameBlock::Storage),
            EVAL_METRICS_SPV.frame_uniform
        );
    }

    #[test]
    fn each_terrain_build_is_compiled_with_its_own_world_and_heights() {
        // naga leaves the branch an override decides in the SPIR-V with a constant condition
        // (the driver drops the dead side), so builds that differ in a value the shader reads
        // differ in their bytes; one that reads neither setting comes out identical.
        let [flat_texture, flat_clipmap, earth_texture, earth_clipmap] = VARIANTS;
        // The GLSL stages get the same settings as `#define`s (glslang, too, leaves the decided
        // branch to the driver).
        for (name, spv) in [
            ("udlod", UDLOD_SPV),
            ("brute", BRUTE_SPV),
            ("tessellation evaluation", TESS_EQUAL_TESE_SPV),
            ("GLSL terrain probe", TERRAIN_PROBE_COMP_SPV),
        ] {
            for block in [FrameBlock::Uniform, FrameBlock::Storage] {
                let bytes = |v| spv.variant(v).bytes(block);
                for (a, b) in [
                    (flat_texture, flat_clipmap),
                    (earth_texture, earth_clipmap),
                    (flat_texture, earth_texture),
                    (flat_clipmap, earth_clipmap),
                ] {
                    assert_ne!(bytes(a), bytes(b), "{name} {block:?}: {a:?} and {b:?}");
                }
            }
        }
        // UDLOD's prepass reads no heights, but culls through the lattice on the earth.
        let tiling = |v| UDLOD_TILING_SPV.variant(v).frame_uniform;
        assert_eq!(tiling(flat_texture), tiling(flat_clipmap));
        assert_ne!(tiling(flat_clipmap), tiling(earth_clipmap));
        // Tessellation control measures its edges through the lattice on the earth and reads
        // its corners' heights from the vertex stage.
        let control = |v| TESS_TESC_SPV.variant(v).frame_uniform;
        assert_eq!(control(flat_texture), control(flat_clipmap));
        assert_ne!(control(flat_texture), control(earth_texture));
    }
}
