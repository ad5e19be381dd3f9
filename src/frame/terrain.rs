//! The GPU mirror of the data set: heights, normals and albedo (or the clipmap's atlas) and
//! one descriptor set 0 with its frame-uniform buffer per view slot
//! (`shaders/include/terrain_common.wgsl`).

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::FrameUniforms;
use crate::dataset::{Heightmap, Level0, Terrain};
use crate::driver::Gpu;
use crate::driver::descriptors::{Binding, DescriptorSets, Resource, stages};
use crate::driver::memory::{Buffer, Image};
use crate::driver::sampler::{Sampler, SamplerInfo};
use crate::driver::shaders::{FrameBlock, TerrainVariant};
use crate::error::{Error, Result};
use crate::slots::ViewSlot;

/// Descriptor set 0, shared by every terrain shader (`shaders/include/terrain_common.wgsl` and
/// `shaders/include/clipmap.wgsl`); every stage may read every binding. The frame's block is a
/// uniform buffer here ([`FrameBlock::Uniform`]); [`terrain_set_for`] picks a device's table.
pub const TERRAIN_SET: &[Binding] =
    &terrain_set(vk::ShaderStageFlags::empty(), FrameBlock::Uniform);

/// [`TERRAIN_SET`] readable by task and mesh stages too: the set 0 of a device with
/// `VK_EXT_mesh_shader` enabled (those stage bits are not valid without it).
pub const TERRAIN_SET_MESH: &[Binding] = &terrain_set(MESH_STAGES, FrameBlock::Uniform);

/// [`TERRAIN_SET`] with the frame's block a read-only storage buffer ([`FrameBlock::Storage`]).
pub const TERRAIN_SET_STORAGE: &[Binding] =
    &terrain_set(vk::ShaderStageFlags::empty(), FrameBlock::Storage);

/// [`TERRAIN_SET_MESH`] with the frame's block a read-only storage buffer.
pub const TERRAIN_SET_MESH_STORAGE: &[Binding] = &terrain_set(MESH_STAGES, FrameBlock::Storage);

const MESH_STAGES: vk::ShaderStageFlags = stages(
    vk::ShaderStageFlags::TASK_EXT,
    vk::ShaderStageFlags::MESH_EXT,
);

/// Set 0's table for `gpu`: with the mesh stages where they are enabled, the frame's block as
/// the device reads it (`Gpu::frame_block`).
pub fn terrain_set_for(gpu: &Gpu) -> &'static [Binding] {
    match (gpu.enabled.mesh_shader, gpu.frame_block) {
        (false, FrameBlock::Uniform) => TERRAIN_SET,
        (true, FrameBlock::Uniform) => TERRAIN_SET_MESH,
        (false, FrameBlock::Storage) => TERRAIN_SET_STORAGE,
        (true, FrameBlock::Storage) => TERRAIN_SET_MESH_STORAGE,
    }
}

/// The set 0 table; `extra` stages on top of every graphics stage and compute.
const fn terrain_set(extra: vk::ShaderStageFlags, frame: FrameBlock) -> [Binding; 10] {
    use vk::DescriptorType as T;
    // Tessellation stages too (hardware tessellation's GLSL stages read the heights).
    const GRAPHICS: vk::ShaderStageFlags = stages(
        vk::ShaderStageFlags::ALL_GRAPHICS,
        vk::ShaderStageFlags::COMPUTE,
    );
    let all = stages(GRAPHICS, extra);
    [
        Binding::new(0, frame.descriptor_type(), all, "frame"),
        Binding::new(1, T::SAMPLED_IMAGE, all, "height_tex"),
        Binding::new(2, T::SAMPLED_IMAGE, all, "normal_tex"),
        Binding::new(3, T::SAMPLED_IMAGE, all, "albedo_tex"),
        Binding::new(4, T::SAMPLER, all, "linear_sampler"),
        // The chunked clipmap: height atlas, the view slot's quadtree, shading atlases.
        Binding::new(5, T::SAMPLED_IMAGE, all, "atlas_height"),
        Binding::new(6, T::STORAGE_BUFFER, all, "clipmap"),
        Binding::new(7, T::SAMPLED_IMAGE, all, "atlas_normal"),
        Binding::new(8, T::SAMPLED_IMAGE, all, "atlas_albedo"),
        // The geolocation lattice (src/geo/lattice.rs); a placeholder node in a flat world.
        Binding::new(9, T::STORAGE_BUFFER, all, "geo_lattice"),
    ]
}

/// The facts about the data set that methods and uniforms need.
#[derive(Clone, Debug)]
pub struct TerrainInfo {
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub spacing: f64,
    pub min_height: f32,
    pub max_height: f32,
    /// The geolocation lattice's `[step, nodes per row, nodes per column, curve radius]` (the
    /// last the f32 bits of [`crate::geo::Lattice::curve_radius`]); None: flat world.
    pub lattice: Option<[u32; 4]>,
}

/// Data-set textures on the GPU plus the set-0 layout and one set per frame slot.
pub struct TerrainGpu {
    pub info: TerrainInfo,
    _height: Image,
    _normal: Image,
    _albedo: Image,
    _lattice: Buffer,
    /// Set 0: one per view slot (they differ in their uniform buffer and clipmap quadtree).
    pub descriptors: DescriptorSets,
    uniforms: Vec<Buffer>,
    /// Binding 4, dropped after the sets that name it.
    _sampler: Sampler,
    /// The build of the terrain shaders that draws this terrain (its world and its source of
    /// heights), as the frame block's `lattice.x` and the clipmap's `params.x` say at run time.
    pub variant: TerrainVariant,
}

impl TerrainGpu {
    /// Set 0 for `slots` view slots. `clipmap`: the clipmap's device mirror bound at bindings 5
    /// (atlas) and 6 (the view slot's quadtree), 7 and 8 (normal and albedo atlases); a
    /// disabled placeholder keeps the single-texture path. `lattice`: where the samples lie
    /// on the earth (binding 9); None: the flat world of docs/coordinates.md.
    pub fn new(
        gpu: &Arc<Gpu>,
        data: &Terrain,
        slots: usize,
        clipmap: &crate::clipmap::gpu::ClipmapGpu,
        lattice: Option<&crate::geo::Lattice>,
    ) -> Result<Self> {
        if let Some(l) = lattice {
            check_lattice_covers(data, l)?;
        }
        let lattice_buffer = lattice_buffer(gpu, lattice)?;
        let (height, normal, albedo) = if clipmap.enabled {
            // Heights, normals and albedo all come through the clipmap's atlas: 1x1
            // placeholders keep the bindings valid without the full-resolution textures.
            placeholder_textures(gpu)?
        } else {
            let data = data.require_grid("the single-texture path (clipmap off)")?;
            Self::textures(gpu, data, lattice)?
        };
        let info = TerrainInfo::new(data, lattice);
        // Binding 4: trilinear, clamped at the edges, anisotropic (up to 16x) where the
        // device enabled it.
        let sampler = Sampler::new(gpu, SamplerInfo::trilinear_clamped().anisotropic(16.0))?;
        let textures = [&height, &normal, &albedo];
        let (descriptors, uniforms) =
            Self::descriptor_sets(gpu, slots, textures, sampler.raw, clipmap, &lattice_buffer)?;
        Ok(TerrainGpu {
            info,
            _height: height,
            _normal: normal,
            _albedo: albedo,
            _lattice: lattice_buffer,
            descriptors,
            uniforms,
            _sampler: sampler,
            variant: TerrainVariant::new(lattice.is_some(), clipmap.enabled),
        })
    }
}

impl TerrainGpu {
    /// Set 0 of every view slot, each with its frame-uniform buffer; `textures`: heights,
    /// normals, albedo.
    fn descriptor_sets(
        gpu: &Arc<Gpu>,
        slots: usize,
        [height, normal, albedo]: [&Image; 3],
        sampler: vk::Sampler,
        clipmap: &crate::clipmap::gpu::ClipmapGpu,
        lattice: &Buffer,
    ) -> Result<(DescriptorSets, Vec<Buffer>)> {
        let descriptors = DescriptorSets::new(gpu, terrain_set_for(gpu), slots)?;
        let mut uniforms = Vec::with_capacity(slots);
        for slot in 0..slots {
            let block = Buffer::new(
                gpu,
                &format!("frame uniforms {slot}"),
                size_of::<FrameUniforms>() as u64,
                gpu.frame_block.buffer_usage(),
                MemoryLocation::CpuToGpu,
            )?;
            descriptors.write(
                slot,
                &[
                    ("frame", Resource::Buffer(block.raw)),
                    ("height_tex", Resource::Image(height.view)),
                    ("normal_tex", Resource::Image(normal.view)),
                    ("albedo_tex", Resource::Image(albedo.view)),
                    ("linear_sampler", Resource::Sampler(sampler)),
                    ("atlas_height", Resource::Image(clipmap.atlas.view)),
                    ("clipmap", Resource::Buffer(clipmap.quadtrees[slot].raw)),
                    ("atlas_normal", Resource::Image(clipmap.normals.view)),
                    ("atlas_albedo", Resource::Image(clipmap.albedo.view)),
                    ("geo_lattice", Resource::Buffer(lattice.raw)),
                ],
            )?;
            uniforms.push(block);
        }
        Ok((descriptors, uniforms))
    }

    /// Descriptor set 0 of `view`.
    pub fn set(&self, view: ViewSlot) -> vk::DescriptorSet {
        self.descriptors.sets[view.index()]
    }

    /// Writes the frame uniforms of `view` (its previous GPU use complete).
    pub fn write_uniforms(&mut self, view: ViewSlot, uniforms: &FrameUniforms) -> Result<()> {
        self.uniforms[view.index()].write(bytemuck::bytes_of(uniforms))
    }

    /// The full-resolution height, normal and albedo textures of the single-texture path.
    fn textures(
        gpu: &Arc<Gpu>,
        data: &Heightmap,
        lattice: Option<&crate::geo::Lattice>,
    ) -> Result<(Image, Image, Image)> {
        let max_side = gpu.info.limits.max_image_dimension2_d;
        if data.width > max_side || data.height > max_side {
            return Err(Error::invalid(
                &data.name,
                format!(
                    "{}x{} exceeds the device's {max_side} texels per side",
                    data.width, data.height
                ),
            ));
        }
        let extent = vk::Extent2D {
            width: data.width,
            height: data.height,
        };
        let heights = bytemuck::cast_slice(&data.heights);
        let height =
            Image::texture_with_data(gpu, "heights", vk::Format::R32_SFLOAT, extent, heights)?;
        let baking = std::time::Instant::now();
        let normals = data.normals_snorm8(lattice);
        tracing::debug!(
            "normal map {}x{} ({} axes) in {:.0} ms",
            data.width,
            data.height,
            if lattice.is_some() { "world" } else { "grid" },
            baking.elapsed().as_secs_f64() * 1e3
        );
        let normal =
            Image::texture_with_data(gpu, "normals", vk::Format::R8G8B8A8_SNORM, extent, &normals)?;
        let albedo_data = data.albedo_or_ramp();
        let albedo = Image::texture_with_data(
            gpu,
            "albedo",
            vk::Format::R8G8B8A8_SRGB,
            vk::Extent2D {
                width: albedo_data.width,
                height: albedo_data.height,
            },
            &albedo_data.rgba,
        )?;
        Ok((height, normal, albedo))
    }
}

impl TerrainInfo {
    /// The facts of `data`, with the geolocation lattice's where it lies on the earth.
    fn new(data: &Terrain, lattice: Option<&crate::geo::Lattice>) -> Self {
        let (min_height, max_height) = data.height_range();
        TerrainInfo {
            name: data.name().to_string(),
            width: data.width(),
            height: data.height(),
            spacing: data.spacing(),
            min_height,
            max_height,
            lattice: lattice.map(|l| {
                let radius = (l.curve_radius() as f32).to_bits();
                [l.step, l.nodes[0], l.nodes[1], radius]
            }),
        }
    }
}

/// Refuses a geolocation lattice whose nodes (one every `step` samples, the last sample
/// included) do not cover `data`.
fn check_lattice_covers(data: &Terrain, l: &crate::geo::Lattice) -> Result<()> {
    let need = [
        (data.width() - 1).div_ceil(l.step) + 1,
        (data.height() - 1).div_ceil(l.step) + 1,
    ];
    if l.nodes != need {
        return Err(Error::invalid(
            data.name(),
            format!(
                "geolocation lattice of {:?} nodes does not cover {}x{} samples",
                l.nodes,
                data.width(),
                data.height()
            ),
        ));
    }
    Ok(())
}

/// Binding 9's buffer: the lattice's nodes, or one placeholder node in the flat world.
fn lattice_buffer(gpu: &Arc<Gpu>, lattice: Option<&crate::geo::Lattice>) -> Result<Buffer> {
    let nodes = lattice.map_or_else(
        || vec![0.0; crate::geo::lattice::NODE_FLOATS],
        |l| l.gpu_nodes(),
    );
    Buffer::with_data(
        gpu,
        "geolocation lattice",
        vk::BufferUsageFlags::STORAGE_BUFFER,
        bytemuck::cast_slice(&nodes),
    )
}

/// Height, normal and albedo textures of one zero texel each.
fn placeholder_textures(gpu: &Arc<Gpu>) -> Result<(Image, Image, Image)> {
    let one = vk::Extent2D {
        width: 1,
        height: 1,
    };
    Ok((
        Image::texture_with_data(gpu, "heights", vk::Format::R32_SFLOAT, one, &[0; 4])?,
        Image::texture_with_data(gpu, "normals", vk::Format::R8G8B8A8_SNORM, one, &[0; 4])?,
        Image::texture_with_data(gpu, "albedo", vk::Format::R8G8B8A8_SRGB, one, &[0; 4])?,
    ))
}
