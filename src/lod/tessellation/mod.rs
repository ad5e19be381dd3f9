//! Hardware tessellation (Fischer 2024): flat triangle patches over the data, refined by the
//! GPU's tessellator. The control stage (GLSL, `shaders/glsl/tess.tesc`) sets each edge's
//! level from the on-screen size of the edge (the diameter of the sphere around it, in
//! pixels, over `edge_px`, times `factor`, clamped to 1..64; the inner level the mean of the
//! outer ones), and discards patches outside the view; the evaluation stage
//! (`shaders/glsl/tess_*.tese`) displaces every generated vertex by the height map through
//! the shared helpers. Levels depend only on an edge's two endpoints, so the two patches on an
//! edge tessellate it alike: no T-junctions by construction.
//!
//! Patches: the data is cut into quads of `patch_samples`² samples, each two triangle patches,
//! corners on samples; one index grid of [`CHUNK_QUADS`]² quads is instanced over the data
//! (like brute force). Per quad the lowest and highest height ([`BlockBounds`]) bound the
//! frustum test. Triangles per frame come from a pipeline-statistics query (primitives
//! reaching the clipper), when the device has the query.
//!
//! The method needs the device feature `tessellationShader` (the TI TDA4VH that Fischer first
//! targeted has none): without it `new` fails with one line naming the feature.

pub mod levels;
pub mod settings;

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::blocks::BlockBounds;
use super::brute::grid_indices;
use super::{LodMethod, MethodContext};
use crate::driver::descriptors::{Binding, DescriptorSets, Resource, stages};
use crate::driver::memory::Buffer;
use crate::driver::pipeline::{
    Pipeline, TerrainPipelineDesc, TessellationStages, tessellated_terrain_pipeline,
};
use crate::driver::{Feature, Gpu};
use crate::error::{Result, VkResultExt};
use crate::frame::ViewState;
use crate::slots::ViewSlot;
use settings::{EdgeLevels, MAX_LEVEL, Spacing, Surface, TessellationSettings};

/// Patch quads per side of the instanced index grid (17² corners: 16-bit indices, 512
/// triangle patches per instance).
pub const CHUNK_QUADS: u32 = 16;

/// Per-view uniforms of set 1 (`Tess` in `shaders/tess.wgsl` and
/// `shaders/glsl/include/tess_common.glsl`; tests prove the layouts equal).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TessUniforms {
    /// x: target edge length (px), y: factor, z: focal length (px), w: highest level.
    pub params: [f32; 4],
    /// x: samples per patch side, y: quads per chunk side, zw: quads per data side.
    pub grid: [u32; 4],
    /// x: frustum culling on (1) or off (0); y: edge levels from the patch centroid (1, an
    /// ablation) or each edge's endpoints (0); z: surface from brute force's triangles (1) or
    /// the bilinear field (0).
    pub flags: [u32; 4],
}

impl TessUniforms {
    /// The uniforms for `quads` patch quads per data side, a view `height` pixels high with a
    /// vertical field of view of `vfov_deg`, on a device whose
    /// `maxTessellationGenerationLevel` is `max_generation_level` (the renderer's and the
    /// CPU mirror's, `levels::LevelRule`).
    pub fn new(
        settings: &TessellationSettings,
        quads: [u32; 2],
        height: u32,
        vfov_deg: f64,
        max_generation_level: u32,
    ) -> Self {
        let focal = height as f64 / (2.0 * (vfov_deg.to_radians() / 2.0).tan());
        TessUniforms {
            params: [
                settings.edge_px as f32,
                settings.factor as f32,
                focal as f32,
                (max_generation_level as f32).min(MAX_LEVEL),
            ],
            grid: [settings.patch_samples, CHUNK_QUADS, quads[0], quads[1]],
            flags: [
                settings.cull as u32,
                (settings.edge_levels == EdgeLevels::Patch) as u32,
                (settings.surface == Surface::Mesh) as u32,
                0,
            ],
        }
    }
}

/// Descriptor set 1: the uniforms (vertex stage: the patch grid; control stage: the levels)
/// and the per-quad height bounds (control stage: culling).
pub const TESS_SET: &[Binding] = {
    use vk::DescriptorType as T;
    // The evaluation stage declares both (one include) and reads the uniforms.
    const TESS: vk::ShaderStageFlags = stages(
        vk::ShaderStageFlags::TESSELLATION_CONTROL,
        vk::ShaderStageFlags::TESSELLATION_EVALUATION,
    );
    &[
        Binding::new(
            0,
            T::UNIFORM_BUFFER,
            stages(vk::ShaderStageFlags::VERTEX, TESS),
            "tess",
        ),
        Binding::new(1, T::STORAGE_BUFFER, TESS, "patch_bounds"),
    ]
};

/// Pipeline statistics read back per view slot, in bit order (as Vulkan returns them):
/// primitives reaching the clipper (the triangles the tessellator made), patches entering
/// the control stage.
const STATISTICS: vk::QueryPipelineStatisticFlags = vk::QueryPipelineStatisticFlags::from_raw(
    vk::QueryPipelineStatisticFlags::TESSELLATION_CONTROL_SHADER_PATCHES.as_raw()
        | vk::QueryPipelineStatisticFlags::CLIPPING_INVOCATIONS.as_raw(),
);

/// The query pool, destroyed in `Drop` (a null handle is valid to destroy).
struct Queries {
    gpu: Arc<Gpu>,
    pool: vk::QueryPool,
}

impl Drop for Queries {
    fn drop(&mut self) {
        unsafe { self.gpu.device.destroy_query_pool(self.pool, None) };
    }
}

pub struct Tessellation {
    gpu: Arc<Gpu>,
    settings: TessellationSettings,
    pipeline: Pipeline,
    indices: Buffer,
    index_count: u32,
    instances: u32,
    /// Patch quads per data side.
    quads: [u32; 2],
    uniforms: Vec<Buffer>,
    sets: DescriptorSets,
    _bounds: Buffer,
    /// `None` where the device has no pipeline-statistics queries.
    queries: Option<Queries>,
    /// Slots whose query was begun (a slot never drawn has no result).
    queried: Vec<bool>,
}

impl Tessellation {
    pub fn new(ctx: &MethodContext<'_>, settings: &TessellationSettings) -> Result<Self> {
        let gpu = ctx.gpu;
        gpu.require(Feature::TessellationShader, "method tessellation")?;
        settings.validate()?;
        let bounds = BlockBounds::new(ctx.data, settings.patch_samples)?;
        let bounds_buffer = Buffer::with_data(
            gpu,
            "tessellation patch bounds",
            vk::BufferUsageFlags::STORAGE_BUFFER,
            bytemuck::cast_slice(&bounds.bounds),
        )?;
        let sets = DescriptorSets::new(gpu, TESS_SET, ctx.slots)?;
        let mut uniforms = Vec::with_capacity(ctx.slots);
        for i in 0..ctx.slots {
            let ubo = Buffer::new(
                gpu,
                &format!("tessellation uniforms {i}"),
                size_of::<TessUniforms>() as u64,
                vk::BufferUsageFlags::UNIFORM_BUFFER,
                MemoryLocation::CpuToGpu,
            )?;
            sets.write(
                i,
                &[
                    ("tess", Resource::Buffer(ubo.raw)),
                    ("patch_bounds", Resource::Buffer(bounds_buffer.raw)),
                ],
            )?;
            uniforms.push(ubo);
        }
        let grid = grid_indices(CHUNK_QUADS);
        let bytes: &[u8] = bytemuck::cast_slice(&grid);
        let indices = Buffer::with_data(
            gpu,
            "tessellation patch indices",
            vk::BufferUsageFlags::INDEX_BUFFER,
            bytes,
        )?;
        let pipeline = Self::pipeline(ctx, settings, sets.layout)?;
        let queries = Self::queries(gpu, ctx.slots)?;
        let chunks = |n: u32| n.div_ceil(CHUNK_QUADS);
        Ok(Tessellation {
            gpu: gpu.clone(),
            settings: settings.clone(),
            pipeline,
            index_count: grid.len() as u32,
            indices,
            instances: chunks(bounds.cols) * chunks(bounds.rows),
            quads: [bounds.cols, bounds.rows],
            uniforms,
            sets,
            _bounds: bounds_buffer,
            queries,
            queried: vec![false; ctx.slots],
        })
    }

    fn pipeline(
        ctx: &MethodContext<'_>,
        settings: &TessellationSettings,
        set1: vk::DescriptorSetLayout,
    ) -> Result<Pipeline> {
        use crate::driver::shaders as s;
        let evaluation_spv = match settings.spacing {
            Spacing::Equal => s::TESS_EQUAL_TESE_SPV,
            Spacing::FractionalOdd => s::TESS_FRACTIONAL_ODD_TESE_SPV,
            Spacing::FractionalEven => s::TESS_FRACTIONAL_EVEN_TESE_SPV,
        };
        tessellated_terrain_pipeline(
            ctx.gpu,
            &ctx.formats,
            &TerrainPipelineDesc {
                spv: s::TESS_SPV.variant(ctx.terrain.variant),
                vertex_entry: c"vs_main",
                fragment_entry: c"fs_main",
                set_layouts: &[ctx.terrain.descriptors.layout, set1],
                topology: vk::PrimitiveTopology::PATCH_LIST,
                cull_back_faces: true,
            },
            &TessellationStages {
                control_spv: s::TESS_TESC_SPV.variant(ctx.terrain.variant),
                evaluation_spv: evaluation_spv.variant(ctx.terrain.variant),
                control_points: 3,
            },
        )
    }

    fn queries(gpu: &Arc<Gpu>, slots: usize) -> Result<Option<Queries>> {
        if !gpu.enabled.pipeline_statistics_query {
            return Ok(None);
        }
        let pool = unsafe {
            gpu.device.create_query_pool(
                &vk::QueryPoolCreateInfo::default()
                    .query_type(vk::QueryType::PIPELINE_STATISTICS)
                    .query_count(slots as u32)
                    .pipeline_statistics(STATISTICS),
                None,
            )
        }
        .vk("vkCreateQueryPool")?;
        Ok(Some(Queries {
            gpu: gpu.clone(),
            pool,
        }))
    }

    /// The uniforms for `view`.
    pub fn uniforms_for(&self, view: &ViewState) -> TessUniforms {
        TessUniforms::new(
            &self.settings,
            self.quads,
            view.height,
            view.camera.vfov_deg,
            self.gpu.info.limits.max_tessellation_generation_level,
        )
    }

    /// `[triangles, patches]` of the last completed frame of `slot`, when queried.
    fn statistics(&self, slot: ViewSlot) -> Option<[u64; 2]> {
        let q = self.queries.as_ref()?;
        if !self.queried[slot.index()] {
            return None;
        }
        let mut out = [[0u64; 2]; 1];
        unsafe {
            self.gpu.device.get_query_pool_results(
                q.pool,
                slot.index() as u32,
                &mut out,
                vk::QueryResultFlags::TYPE_64,
            )
        }
        .ok()?;
        Some(out[0])
    }
}

impl LodMethod for Tessellation {
    fn name(&self) -> &'static str {
        "tessellation"
    }

    fn update(&mut self, slot: ViewSlot, view: &ViewState) -> Result<()> {
        let u = self.uniforms_for(view);
        self.uniforms[slot.index()].write(bytemuck::bytes_of(&u))
    }

    fn record_prepass(&mut self, cmd: vk::CommandBuffer, slot: ViewSlot, _: vk::DescriptorSet) {
        if let Some(q) = &self.queries {
            unsafe {
                self.gpu
                    .device
                    .cmd_reset_query_pool(cmd, q.pool, slot.index() as u32, 1)
            };
        }
    }

    fn record_draw(
        &mut self,
        cmd: vk::CommandBuffer,
        slot: ViewSlot,
        frame_set: vk::DescriptorSet,
    ) {
        let d = &self.gpu.device;
        let query = self.queries.as_ref().map(|q| (q.pool, slot.index() as u32));
        unsafe {
            self.pipeline.bind(
                cmd,
                vk::PipelineBindPoint::GRAPHICS,
                &[frame_set, self.sets.sets[slot.index()]],
            );
            d.cmd_bind_index_buffer(cmd, self.indices.raw, 0, vk::IndexType::UINT16);
            if let Some((pool, i)) = query {
                d.cmd_begin_query(cmd, pool, i, vk::QueryControlFlags::empty());
            }
            // One draw per row of patch quads: lavapipe (Mesa 22.3) dropped the later patches
            // of one draw when it tessellated hundreds of thousands of triangles
            // (docs/tessellation.md); rows past the data are not drawn.
            let row_indices = self.index_count / CHUNK_QUADS;
            let chunks_x = self.quads[0].div_ceil(CHUNK_QUADS);
            for instance in 0..self.instances {
                let chunk_y = instance / chunks_x;
                let rows = (self.quads[1] - chunk_y * CHUNK_QUADS).min(CHUNK_QUADS);
                for row in 0..rows {
                    d.cmd_draw_indexed(cmd, row_indices, 1, row * row_indices, 0, instance);
                }
            }
            if let Some((pool, i)) = query {
                d.cmd_end_query(cmd, pool, i);
            }
        }
        self.queried[slot.index()] = query.is_some();
    }

    /// Primitives that reached the clipper (the tessellator's triangles after culled patches),
    /// or 0 where the device cannot count them.
    fn triangles(&self, slot: ViewSlot) -> u64 {
        self.statistics(slot).map_or(0, |s| s[0])
    }

    fn counters(&self, slot: ViewSlot) -> Vec<(&'static str, u64)> {
        let patches = 2 * self.quads[0] as u64 * self.quads[1] as u64;
        let mut out = vec![("patches", patches)];
        if let Some([_, control]) = self.statistics(slot) {
            out.push(("control_stage_patches", control));
        }
        out
    }
}
