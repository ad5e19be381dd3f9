//! GPU chunked LOD (Hedberg 2022): the quadtree of chunks selected on the GPU in compute, by
//! screen-space error (each chunk's geometric error from the data's tile statistics,
//! projected at its bounding sphere's distance, against a pixel threshold) with
//! bounding-sphere frustum culling, then one chunk mesh instanced per selected chunk through
//! one indexed indirect draw. Cracks are closed by his edge patching: the selection writes a
//! LOD map (each level-0 cell's chunk level) and the vertex stage snaps edge vertices onto a
//! coarser neighbour's grid (`shaders/chunked.wgsl`).
//!
//! Two traversals ([`Traversal`]): the naive walk, level by level every frame, and the
//! concurrent binary tree (CBT) that persists per frame slot and moves one split/merge step
//! per frame (`shaders/chunked_select.wgsl`). The CPU reference is [`select`]; the chunk
//! statistics are UDLOD's ([`Levels`], the same per-tile min/max and errors).

#[cfg(feature = "test-support")]
pub mod probe;
mod record;
pub mod select;
pub mod settings;

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::MethodContext;
use crate::dataset::stats::{Finest, TileStats};
use crate::dataset::{Level0, Terrain};
use crate::driver::Gpu;
use crate::driver::descriptors::{Binding, DescriptorSets, Resource, stages};
use crate::driver::device::Feature;
use crate::driver::memory::Buffer;
use crate::driver::pipeline::{
    Pipeline, TerrainPipelineDesc, compute_pipeline, mesh_terrain_pipeline, terrain_pipeline,
};
use crate::error::{Error, Result};
use crate::frame::ViewState;
use crate::gpu_constants::UDLOD_MAX_LEVELS;
use crate::lod::udlod::levels::Levels;
use crate::slots::ViewSlot;
use select::{CbtLayout, ChunkParams, Depths};
pub use settings::{ChunkDraw, ChunkedSettings, Traversal};

/// Per-frame uniforms of set 1 (`Chunked` in `shaders/include/chunked_common.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ChunkedUniforms {
    pub frustum: [[f32; 4]; 6],
    pub levels: [[u32; 4]; UDLOD_MAX_LEVELS as usize],
    pub viewer: [f32; 4],
    pub params: [f32; 4],
    pub sizes: [u32; 4],
    pub lists: [u32; 4],
    pub cbt: [u32; 4],
    /// xy: the LOD metric's stretch per axis ([`select::ChunkParams::stretch`]).
    pub metric: [f32; 4],
}

/// The selection state the GPU keeps per slot (`ChunkState` in `shaders/chunked_select.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ChunkState {
    pub dispatch: [u32; 3],
    pub pass_index: u32,
    pub draw: [u32; 5],
    pub map: [u32; 3],
    pub current_count: u32,
    pub next_count: u32,
    pub final_count: u32,
    pub overflow: u32,
    pub culled: u32,
    pub passes_started: u32,
    pub splits: u32,
    pub merges: u32,
    pub mesh: [u32; 3],
}

/// Where `ChunkState::draw` starts: the `vkCmdDrawIndexedIndirect` arguments.
pub const DRAW_OFFSET: u64 = std::mem::offset_of!(ChunkState, draw) as u64;
/// Where `ChunkState::map` starts: the LOD-map pass's `vkCmdDispatchIndirect` arguments.
pub const MAP_OFFSET: u64 = std::mem::offset_of!(ChunkState, map) as u64;
/// Where `ChunkState::mesh` starts: the `vkCmdDrawMeshTasksIndirectEXT` arguments.
pub const MESH_OFFSET: u64 = std::mem::offset_of!(ChunkState, mesh) as u64;
pub const CHUNK_BYTES: u64 = 16;
/// The deepest CBT allowed (binary depth): 64 MiB of sums; one level deeper (256 MiB) is
/// beyond what one storage buffer may hold on many devices (lavapipe: 128 MiB).
pub const CBT_MAX_DEPTH: u32 = 24;

/// Descriptor set 1 (`shaders/include/chunked_common.wgsl`, `shaders/chunked_select.wgsl`,
/// `shaders/chunked.wgsl`).
pub const CHUNKED_SET: &[Binding] = &chunked_set(vk::ShaderStageFlags::empty());

/// [`CHUNKED_SET`] with the draw's bindings readable by task and mesh stages too (the mesh
/// path, `shaders/glsl/include/chunked_common.glsl`).
pub const CHUNKED_SET_MESH: &[Binding] = &chunked_set(stages(
    vk::ShaderStageFlags::TASK_EXT,
    vk::ShaderStageFlags::MESH_EXT,
));

/// The set 1 table; `draw_extra`: stages beyond compute and vertex that draw with it.
const fn chunked_set(draw_extra: vk::ShaderStageFlags) -> [Binding; 9] {
    use vk::DescriptorType as T;
    const C: vk::ShaderStageFlags = vk::ShaderStageFlags::COMPUTE;
    let cv = stages(
        stages(vk::ShaderStageFlags::COMPUTE, vk::ShaderStageFlags::VERTEX),
        draw_extra,
    );
    [
        Binding::new(0, T::UNIFORM_BUFFER, cv, "chunked"),
        Binding::new(1, T::STORAGE_BUFFER, C, "state"),
        Binding::new(2, T::STORAGE_BUFFER, C, "lists"),
        Binding::new(3, T::STORAGE_BUFFER, cv, "final_chunks"),
        Binding::new(4, T::STORAGE_BUFFER, C, "min_max"),
        Binding::new(5, T::STORAGE_BUFFER, C, "chunk_error"),
        Binding::new(6, T::STORAGE_BUFFER, cv, "lod_map"),
        Binding::new(7, T::STORAGE_BUFFER, C, "cbt_heap"),
        Binding::new(8, T::STORAGE_BUFFER, C, "cbt_bits"),
    ]
}

struct SlotBuffers {
    uniforms: Buffer,
    state: Buffer,
    _lists: Buffer,
    #[cfg_attr(not(feature = "test-support"), allow(dead_code))]
    final_chunks: Buffer,
    lod_map: Buffer,
    _cbt_heap: Buffer,
    _cbt_bits: Buffer,
    /// Host-readable copy of `state` (counters for statistics).
    counters: Buffer,
    set: vk::DescriptorSet,
}

struct Pipelines {
    prepare: Pipeline,
    refine: Pipeline,
    cbt_begin: Pipeline,
    cbt_update: Pipeline,
    cbt_reduce_bits: Pipeline,
    cbt_reduce: Pipeline,
    cbt_reduce_top: Pipeline,
    cbt_list: Pipeline,
    finish: Pipeline,
    lod_map: Pipeline,
    draw: Pipeline,
}

impl Pipelines {
    fn new(
        ctx: &MethodContext<'_>,
        set_layouts: &[vk::DescriptorSetLayout],
        draw: ChunkDraw,
    ) -> Result<Self> {
        let gpu = ctx.gpu;
        let spv = crate::driver::shaders::CHUNKED_SELECT_SPV.variant(ctx.terrain.variant);
        let c = |entry: &std::ffi::CStr| compute_pipeline(gpu, spv, entry, set_layouts);
        Ok(Pipelines {
            prepare: c(c"prepare")?,
            refine: c(c"refine")?,
            cbt_begin: c(c"cbt_begin")?,
            cbt_update: c(c"cbt_update")?,
            cbt_reduce_bits: c(c"cbt_reduce_bits")?,
            cbt_reduce: c(c"cbt_reduce")?,
            cbt_reduce_top: c(c"cbt_reduce_top")?,
            cbt_list: c(c"cbt_list")?,
            finish: c(c"finish")?,
            lod_map: c(c"lod_map_fill")?,
            draw: Self::draw(ctx, set_layouts, draw)?,
        })
    }

    fn draw(
        ctx: &MethodContext<'_>,
        set_layouts: &[vk::DescriptorSetLayout],
        draw: ChunkDraw,
    ) -> Result<Pipeline> {
        let desc = TerrainPipelineDesc {
            cull_back_faces: false,
            ..TerrainPipelineDesc::triangles(
                crate::driver::shaders::CHUNKED_SPV.variant(ctx.terrain.variant),
                set_layouts,
            )
        };
        match draw {
            ChunkDraw::Instanced => terrain_pipeline(ctx.gpu, &ctx.formats, &desc),
            ChunkDraw::Mesh => mesh_terrain_pipeline(
                ctx.gpu,
                &ctx.formats,
                &desc,
                crate::driver::shaders::CHUNKED_TASK_SPV.variant(ctx.terrain.variant),
                crate::driver::shaders::CHUNKED_MESH_SPV.variant(ctx.terrain.variant),
            ),
        }
    }
}

pub struct Chunked {
    gpu: Arc<Gpu>,
    settings: ChunkedSettings,
    levels: Levels,
    depths: Depths,
    /// The geolocation lattice (None: the flat world), for the CPU reference's curved boxes.
    lattice: Option<Arc<crate::geo::Lattice>>,
    cbt: CbtLayout,
    _min_max: Buffer,
    _errors: Buffer,
    indices: Buffer,
    index_count: u32,
    slots: Vec<SlotBuffers>,
    /// Set 1 of every slot (`SlotBuffers::set`).
    #[cfg_attr(not(feature = "test-support"), allow(dead_code))]
    sets: DescriptorSets,
    pipelines: Pipelines,
    /// The mesh-shader entry points (`draw = "mesh"`).
    mesh: Option<ash::ext::mesh_shader::Device>,
}

/// A host-written storage buffer holding `bytes`.
fn host_buffer(gpu: &Arc<Gpu>, name: &str, bytes: &[u8]) -> Result<Buffer> {
    Buffer::with_data(gpu, name, vk::BufferUsageFlags::STORAGE_BUFFER, bytes)
}

/// A device-local storage buffer initialised with `bytes` through a staging copy.
fn device_buffer(gpu: &Arc<Gpu>, name: &str, bytes: &[u8]) -> Result<Buffer> {
    let b = Buffer::new(
        gpu,
        name,
        bytes.len() as u64,
        vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_DST,
        MemoryLocation::GpuOnly,
    )?;
    let staging = Buffer::new(
        gpu,
        &format!("{name} staging"),
        bytes.len() as u64,
        vk::BufferUsageFlags::TRANSFER_SRC,
        MemoryLocation::CpuToGpu,
    );
    let mut staging = staging?;
    staging.write(bytes)?;
    let region = vk::BufferCopy {
        src_offset: 0,
        dst_offset: 0,
        size: bytes.len() as u64,
    };
    gpu.one_shot(|cmd| unsafe {
        gpu.device
            .cmd_copy_buffer(cmd, staging.raw, b.raw, &[region]);
    })?;
    Ok(b)
}

impl Chunked {
    pub fn new(ctx: &MethodContext<'_>, settings: &ChunkedSettings) -> Result<Self> {
        let gpu = ctx.gpu;
        settings.validate()?;
        let settings = settings.clone();
        let levels = Self::chunk_levels(ctx, &settings)?;
        let depths = Depths::new(&levels, &settings);
        let cbt = Self::cbt_layout(gpu, &settings, depths)?;
        let sets = DescriptorSets::new(gpu, Self::set_table(gpu, settings.draw)?, ctx.slots)?;
        let min_max = host_buffer(
            gpu,
            "chunked min/max",
            bytemuck::cast_slice(&levels.min_max),
        )?;
        let errors = host_buffer(
            gpu,
            "chunked errors",
            bytemuck::cast_slice(&levels.tile_error),
        )?;
        let grid = super::brute::grid_indices(settings.chunk_quads);
        let indices = Buffer::with_data(
            gpu,
            "chunked grid indices",
            vk::BufferUsageFlags::INDEX_BUFFER,
            bytemuck::cast_slice(&grid),
        )?;
        let shared = [&min_max, &errors];
        let slots = Self::bound_slots(ctx, &settings, &levels, (depths, cbt), &sets, shared)?;
        let set_layouts = [ctx.terrain.descriptors.layout, sets.layout];
        let pipelines = Pipelines::new(ctx, &set_layouts, settings.draw)?;
        log_layout(&settings, depths, cbt);
        let mesh = (settings.draw == ChunkDraw::Mesh)
            .then(|| ash::ext::mesh_shader::Device::new(&gpu.instance.raw, &gpu.device));
        Ok(Chunked {
            gpu: gpu.clone(),
            settings,
            levels,
            depths,
            lattice: ctx.lattice.cloned(),
            cbt,
            _min_max: min_max,
            _errors: errors,
            indices,
            index_count: grid.len() as u32,
            slots,
            sets,
            pipelines,
            mesh,
        })
    }

    /// The method's descriptor set table for `draw` (the mesh draw's needs the mesh shader).
    fn set_table(gpu: &Gpu, draw: ChunkDraw) -> Result<&'static [Binding]> {
        Ok(match draw {
            ChunkDraw::Instanced => CHUNKED_SET,
            ChunkDraw::Mesh => {
                gpu.require(
                    Feature::MeshShader,
                    "method chunked with draw = \"mesh\" (VK_EXT_mesh_shader)",
                )?;
                CHUNKED_SET_MESH
            }
        })
    }

    /// Each frame slot's buffers, bound into its descriptor set beside the statistics
    /// `[min_max, errors]` all slots share.
    fn bound_slots(
        ctx: &MethodContext<'_>,
        settings: &ChunkedSettings,
        levels: &Levels,
        (depths, cbt): (Depths, CbtLayout),
        sets: &DescriptorSets,
        [min_max, errors]: [&Buffer; 2],
    ) -> Result<Vec<SlotBuffers>> {
        let mut slots = Vec::with_capacity(ctx.slots);
        for i in 0..ctx.slots {
            let s = Self::slot_buffers(ctx.gpu, settings, levels, depths, cbt, sets, i)?;
            sets.write(
                i,
                &[
                    ("chunked", Resource::Buffer(s.uniforms.raw)),
                    ("state", Resource::Buffer(s.state.raw)),
                    ("lists", Resource::Buffer(s._lists.raw)),
                    ("final_chunks", Resource::Buffer(s.final_chunks.raw)),
                    ("min_max", Resource::Buffer(min_max.raw)),
                    ("chunk_error", Resource::Buffer(errors.raw)),
                    ("lod_map", Resource::Buffer(s.lod_map.raw)),
                    ("cbt_heap", Resource::Buffer(s._cbt_heap.raw)),
                    ("cbt_bits", Resource::Buffer(s._cbt_bits.raw)),
                ],
            )?;
            slots.push(s);
        }
        Ok(slots)
    }

    /// The chunk quadtree's statistics (a pyramid's stored ones, else computed from level 0).
    fn chunk_levels(ctx: &MethodContext<'_>, settings: &ChunkedSettings) -> Result<Levels> {
        let (stats, spacing) = match ctx.data {
            Terrain::Grid(h) => (
                TileStats::compute(&**h, settings.chunk_quads, &|_| {})?,
                h.spacing,
            ),
            Terrain::Pyramid(p) => (
                p.tile_stats(settings.chunk_quads, Finest::Keep)?,
                p.spacing(),
            ),
        };
        // Level 0's chunks are culled and bounded with their own heights (the shaders read
        // them), unlike UDLOD's level-0 tiles.
        let mut levels = Levels::from_stats_with_finest(stats, spacing);
        if let (Some(lattice), settings::LodMetric::Axis) = (ctx.lattice, settings.lod_metric) {
            levels = levels.on_lattice(ctx.data.axis_spacing(), lattice);
        }
        if levels.levels() > UDLOD_MAX_LEVELS {
            return Err(Error::invalid(
                "chunked",
                format!(
                    "{} levels exceed the maximum of {UDLOD_MAX_LEVELS}; raise chunk_quads",
                    levels.levels()
                ),
            ));
        }
        Ok(levels)
    }

    /// The CBT of this tree depth, or a one-line error when it cannot be one buffer.
    fn cbt_layout(gpu: &Gpu, settings: &ChunkedSettings, depths: Depths) -> Result<CbtLayout> {
        let cbt = CbtLayout::for_quad_depth(depths.tree_depth());
        if settings.traversal != Traversal::Cbt {
            return Ok(cbt);
        }
        let limit = gpu.info.limits.max_storage_buffer_range as u64;
        if cbt.depth > CBT_MAX_DEPTH || cbt.heap_bytes() > limit {
            return Err(Error::invalid(
                "chunked",
                format!(
                    "a CBT of tree depth {} needs {} MB of sums in one buffer (device limit \
                     maxStorageBufferRange {} MB, vkterrain's {} MB); lower max_depth or raise \
                     chunk_quads",
                    depths.tree_depth(),
                    cbt.heap_bytes() / 1_000_000,
                    limit / 1_000_000,
                    CbtLayout {
                        depth: CBT_MAX_DEPTH
                    }
                    .heap_bytes()
                        / 1_000_000
                ),
            ));
        }
        Ok(cbt)
    }

    fn slot_buffers(
        gpu: &Arc<Gpu>,
        settings: &ChunkedSettings,
        levels: &Levels,
        depths: Depths,
        cbt: CbtLayout,
        sets: &DescriptorSets,
        i: usize,
    ) -> Result<SlotBuffers> {
        let storage = vk::BufferUsageFlags::STORAGE_BUFFER;
        let buffer = |name: &str, size: u64, usage, location| {
            Buffer::new(gpu, &format!("chunked {name} {i}"), size, usage, location)
        };
        let cap = settings.max_chunks as u64;
        let (nx, ny) = levels.tiles_per_side[0];
        let (heap, bits) = Self::cbt_buffers(gpu, settings, depths, cbt, i)?;
        Ok(SlotBuffers {
            uniforms: buffer(
                "uniforms",
                size_of::<ChunkedUniforms>() as u64,
                vk::BufferUsageFlags::UNIFORM_BUFFER,
                MemoryLocation::CpuToGpu,
            )?,
            state: buffer(
                "state",
                size_of::<ChunkState>() as u64,
                storage
                    | vk::BufferUsageFlags::INDIRECT_BUFFER
                    | vk::BufferUsageFlags::TRANSFER_DST
                    | vk::BufferUsageFlags::TRANSFER_SRC,
                MemoryLocation::GpuOnly,
            )?,
            _lists: buffer(
                "lists",
                2 * cap * CHUNK_BYTES,
                storage,
                MemoryLocation::GpuOnly,
            )?,
            final_chunks: buffer(
                "render list",
                cap * CHUNK_BYTES,
                storage | vk::BufferUsageFlags::TRANSFER_SRC,
                MemoryLocation::GpuOnly,
            )?,
            lod_map: buffer(
                "lod map",
                nx as u64 * ny as u64 * 4,
                storage | vk::BufferUsageFlags::TRANSFER_DST,
                MemoryLocation::GpuOnly,
            )?,
            _cbt_heap: heap,
            _cbt_bits: bits,
            counters: buffer(
                "counters",
                size_of::<ChunkState>() as u64,
                vk::BufferUsageFlags::TRANSFER_DST,
                MemoryLocation::GpuToCpu,
            )?,
            set: sets.sets[i],
        })
    }

    /// The CBT's heap and bit field for slot `i`, at the tree's initial subdivision; a
    /// placeholder pair for the naive walk, whose set binds them unused.
    fn cbt_buffers(
        gpu: &Arc<Gpu>,
        settings: &ChunkedSettings,
        depths: Depths,
        cbt: CbtLayout,
        i: usize,
    ) -> Result<(Buffer, Buffer)> {
        let (heap, bits) = if settings.traversal == Traversal::Cbt {
            cbt.initial(depths.root - depths.start)
        } else {
            (vec![0; 4], vec![0; 4])
        };
        Ok((
            device_buffer(
                gpu,
                &format!("chunked cbt heap {i}"),
                bytemuck::cast_slice(&heap),
            )?,
            device_buffer(
                gpu,
                &format!("chunked cbt bits {i}"),
                bytemuck::cast_slice(&bits),
            )?,
        ))
    }

    pub fn levels(&self) -> &Levels {
        &self.levels
    }

    /// The CBT's layout for this tree (its memory per frame slot: `total_bytes`).
    pub fn cbt_layout_of(&self) -> CbtLayout {
        self.cbt
    }

    /// The selection inputs for a view, exactly as uploaded (tests use them for the CPU
    /// reference).
    pub fn params(&self, view: &ViewState) -> ChunkParams {
        let p = ChunkParams::new(
            &self.levels,
            &self.settings,
            &view.camera,
            view.lod_viewer,
            view.width,
            view.height,
        );
        match &self.lattice {
            Some(l) => p.on_earth(&self.levels, l.clone(), view.camera.position),
            None => p,
        }
    }

    fn read_counters(&self, slot: ViewSlot) -> ChunkState {
        self.slots[slot.index()]
            .counters
            .mapped()
            .and_then(|bytes| bytes.get(..size_of::<ChunkState>()))
            .map(bytemuck::pod_read_unaligned)
            .unwrap_or_default()
    }
}

#[cfg(feature = "test-support")]
impl Chunked {
    /// Tests only: the render list of the last completed frame of `slot`, as `[x, y, lod]`.
    pub fn debug_chunks(&self, slot: ViewSlot) -> Result<Vec<[u32; 3]>> {
        let n = self.read_counters(slot).draw[1] as u64;
        if n == 0 {
            return Ok(Vec::new());
        }
        let host = Buffer::new(
            &self.gpu,
            "chunked debug list",
            n * CHUNK_BYTES,
            vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuToCpu,
        )?;
        let src = self.slots[slot.index()].final_chunks.raw;
        use crate::driver::barrier::{Barriers, MemoryAccess};
        let b = Barriers::new(&self.gpu);
        self.gpu.one_shot(|cmd| {
            b.copy_for_host(
                cmd,
                MemoryAccess::PreviousFrame,
                (src, 0),
                host.raw,
                n * CHUNK_BYTES,
            )
        })?;
        let bytes = host
            .mapped()
            .and_then(|b| b.get(..(n * CHUNK_BYTES) as usize))
            .ok_or_else(|| Error::invalid("chunked", "debug buffer not mapped"))?;
        let chunks: Vec<[u32; 4]> = bytemuck::pod_collect_to_vec(bytes);
        Ok(chunks.iter().map(|t| [t[0], t[1], t[2]]).collect())
    }
}

/// The method's shape in the log: traversal, draw, chunk size, levels and the CBT it would need.
fn log_layout(settings: &ChunkedSettings, depths: Depths, cbt: CbtLayout) {
    tracing::info!(
        "chunked: {} traversal, {} draw, {} quads per chunk, levels {}..={} (tree depth {}, root depth \
         {}); a CBT of this tree: binary depth {}, {} bytes of sums + {} bytes of bits per slot",
        settings.traversal.name(),
        settings.draw.name(),
        settings.chunk_quads,
        depths.finest,
        depths.root,
        depths.tree_depth(),
        depths.root - depths.start,
        cbt.depth,
        cbt.heap_bytes(),
        cbt.bit_bytes()
    );
}
