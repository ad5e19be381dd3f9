//! UDLOD's GPU mirrors: set 1's per-frame block and tiling state as the shaders read them
//! (`shaders/include/udlod_common.wgsl`, `shaders/udlod_tiling.wgsl`; layouts proven by
//! `tests/shader_interface.rs`), the draw groups, and each frame slot's buffers and tile lists.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::field::FieldKey;
use super::grid::TileMask;
use crate::driver::Gpu;
use crate::driver::descriptors::{Binding, DescriptorSets, Resource, stages};
use crate::driver::memory::Buffer;
use crate::error::Result;
use crate::gpu_constants::{UDLOD_MAX_LEVELS, UDLOD_SEED_TILES, UDLOD_TILE_MASKS};

/// Per-frame uniforms of set 1 (`Udlod` in `shaders/include/udlod_common.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct UdlodUniforms {
    pub frustum: [[f32; 4]; 6],
    pub split: [[f32; 4]; UDLOD_MAX_LEVELS as usize],
    pub levels: [[u32; 4]; UDLOD_MAX_LEVELS as usize],
    pub sizes: [u32; 4],
    pub params: [f32; 4],
    pub viewer: [f32; 4],
    pub counts: [u32; 4],
    /// xy: the LOD metric's stretch per axis ([`super::levels::Levels::stretch`]).
    pub metric: [f32; 4],
    /// Per draw mask ([`super::grid::TileMask`]): its indices (vertices with vertex pulling) per tile
    /// and first index ([`super::grid::IndexLayout`]).
    pub masks: [[u32; 4]; UDLOD_TILE_MASKS as usize],
    /// The first pass's parents from the host ([`super::seed::Seed`]): x tiles, y those that split.
    pub seed: [u32; 4],
}

impl Default for UdlodUniforms {
    fn default() -> Self {
        bytemuck::Zeroable::zeroed()
    }
}

/// Indirect draws per slot: static tiles per draw mask, then morphing ones.
pub const DRAW_GROUPS: usize = 2 * UDLOD_TILE_MASKS as usize;

/// The tiling state the GPU keeps per slot (`TilingState` in `shaders/udlod_tiling.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TilingState {
    pub dispatch: [u32; 3],
    pub pass_index: u32,
    pub parent_count: u32,
    pub child_count: u32,
    /// Final tiles of the frame (every group).
    pub final_count: u32,
    pub reserved_leaves: u32,
    pub overflow: u32,
    pub culled: u32,
    pub passes_started: u32,
    pub splits_allowed: u32,
    pub split_requests: u32,
    /// Draws with tiles: the static groups' from `draws[0]`, the morphing groups' from
    /// `draws[UDLOD_TILE_MASKS]`.
    pub static_draws: u32,
    pub morphing_draws: u32,
    /// Final tiles per draw group (static per draw mask, then morphing), and where each
    /// group starts in the final list's sorted half.
    pub group_count: [u32; DRAW_GROUPS],
    pub group_first: [u32; DRAW_GROUPS],
    /// The groups' `VkDrawIndexedIndirectCommand`s (with vertex pulling
    /// `VkDrawIndirectCommand`s in the first four words), only those with tiles, then draws
    /// of no instance.
    pub draws: [[u32; 5]; DRAW_GROUPS],
}

impl Default for TilingState {
    fn default() -> Self {
        bytemuck::Zeroable::zeroed()
    }
}

impl TilingState {
    /// Tiles drawn per draw group: the groups' counts, or none in a frame whose final tiles
    /// did not fit the list (`finish` then gives every draw 0 instances, so the draws' sum
    /// falls short of `final_count`).
    pub fn drawn(&self) -> [u64; DRAW_GROUPS] {
        let instances: u64 = self.draws.iter().map(|d| u64::from(d[1])).sum();
        let drew_all = instances == u64::from(self.final_count);
        self.group_count
            .map(|n| if drew_all { u64::from(n) } else { 0 })
    }
}

/// A draw group's mask and whether its tiles morph (drawn without back-face culling by
/// default).
pub fn draw_group(group: usize) -> (TileMask, bool) {
    let masks = UDLOD_TILE_MASKS as usize;
    (TileMask::from_index((group % masks) as u32), group >= masks)
}

/// Descriptor set 1 (`shaders/include/udlod_common.wgsl`, `shaders/udlod_tiling.wgsl`,
/// `shaders/udlod.wgsl`): the tiling passes and the vertex shaders (and the morph probe).
pub const UDLOD_SET: &[Binding] = {
    use vk::DescriptorType as T;
    const CV: vk::ShaderStageFlags =
        stages(vk::ShaderStageFlags::COMPUTE, vk::ShaderStageFlags::VERTEX);
    &[
        Binding::new(0, T::UNIFORM_BUFFER, CV, "udlod"),
        Binding::new(1, T::STORAGE_BUFFER, CV, "state"),
        Binding::new(2, T::STORAGE_BUFFER, CV, "temp_tiles"),
        Binding::new(3, T::STORAGE_BUFFER, CV, "final_tiles"),
        Binding::new(4, T::STORAGE_BUFFER, CV, "min_max"),
        Binding::new(5, T::STORAGE_BUFFER, CV, "split_field"),
    ]
};

/// Where `TilingState::draws` starts: the static groups' draws, then the morphing groups'.
pub const DRAWS_OFFSET: u64 = std::mem::offset_of!(TilingState, draws) as u64;
/// Where the static and the morphing draws' counts are (`vkCmdDraw*IndirectCount`).
pub const STATIC_DRAWS_OFFSET: u64 = std::mem::offset_of!(TilingState, static_draws) as u64;
pub const MORPHING_DRAWS_OFFSET: u64 = std::mem::offset_of!(TilingState, morphing_draws) as u64;
/// Bytes between consecutive indirect draws.
pub const DRAW_STRIDE: u32 = size_of::<[u32; 5]>() as u32;
pub const TILE_BYTES: u64 = 16;

pub(super) struct SlotBuffers {
    pub(super) uniforms: Buffer,
    pub(super) state: Buffer,
    pub(super) lists: TileLists,
    /// Host-readable copy of `state` (counters for statistics).
    pub(super) counters: Buffer,
    /// The split field's corner values this slot draws with, and what they were built for
    /// (rewritten only when that changes: a frame in flight keeps its own copy).
    pub(super) field: Buffer,
    pub(super) field_key: Option<FieldKey>,
    /// The coarse levels' tiles decided on the host for this slot's next frame
    /// ([`super::seed::seed`]; `UDLOD_SEED_TILES` entries), copied to the front of the temporary
    /// list before the first pass, and the passes recorded after them.
    pub(super) seed: Buffer,
    pub(super) seed_tiles: u32,
    pub(super) passes: u32,
    pub(super) set: vk::DescriptorSet,
    /// Whether a frame was recorded on this slot (its counters hold a frame's).
    pub(super) drawn: bool,
}

/// A slot's tile lists: the final list the draw reads and the temporary one the passes of
/// the prepass share.
pub(super) struct TileLists {
    /// Read and written by the prepass only (through the descriptor set).
    pub(super) temp: Buffer,
    /// The final tiles as the prepass writes them (`capacity` entries, unsorted), then the
    /// same sorted by draw group (`scatter`), which the draws read.
    #[cfg_attr(not(feature = "test-support"), allow(dead_code))]
    pub(super) final_tiles: Buffer,
    /// Entries of each half of the final list.
    pub(super) capacity: u32,
}

impl TileLists {
    /// Lists for `capacity` final tiles. Parents and children of one pass share the
    /// temporary list: a pass has at most `4/3 * capacity + 1` children (every split
    /// reserved 3 final entries).
    pub(super) fn new(gpu: &Arc<Gpu>, i: usize, capacity: u32) -> Result<Self> {
        let storage = vk::BufferUsageFlags::STORAGE_BUFFER;
        let temp = Buffer::new(
            gpu,
            &format!("udlod temp tiles {i}"),
            Self::temp_capacity(capacity) as u64 * TILE_BYTES,
            storage | vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuOnly,
        )?;
        let final_tiles = Buffer::new(
            gpu,
            &format!("udlod final tiles {i}"),
            2 * capacity as u64 * TILE_BYTES,
            storage | vk::BufferUsageFlags::TRANSFER_SRC,
            MemoryLocation::GpuOnly,
        )?;
        Ok(TileLists {
            temp,
            final_tiles,
            capacity,
        })
    }

    pub(super) fn temp_capacity(capacity: u32) -> u32 {
        2 * capacity + 8
    }
}

impl SlotBuffers {
    /// Slot `i`'s buffers with lists for `capacity` tiles and a split field of `field_bytes`,
    /// written into its descriptor set `set` with the shared `min_max`.
    pub(super) fn new(
        gpu: &Arc<Gpu>,
        sets: &DescriptorSets,
        (i, set): (usize, vk::DescriptorSet),
        (capacity, field_bytes): (u32, u64),
        min_max: &Buffer,
    ) -> Result<Self> {
        let storage = vk::BufferUsageFlags::STORAGE_BUFFER;
        let uniforms = Buffer::new(
            gpu,
            &format!("udlod uniforms {i}"),
            size_of::<UdlodUniforms>() as u64,
            vk::BufferUsageFlags::UNIFORM_BUFFER,
            MemoryLocation::CpuToGpu,
        )?;
        let state = Buffer::new(
            gpu,
            &format!("udlod state {i}"),
            size_of::<TilingState>() as u64,
            storage
                | vk::BufferUsageFlags::INDIRECT_BUFFER
                | vk::BufferUsageFlags::TRANSFER_DST
                | vk::BufferUsageFlags::TRANSFER_SRC,
            MemoryLocation::GpuOnly,
        )?;
        let counters = Buffer::new(
            gpu,
            &format!("udlod counters {i}"),
            size_of::<TilingState>() as u64,
            vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuToCpu,
        )?;
        let field = Buffer::new(
            gpu,
            &format!("udlod split field {i}"),
            field_bytes,
            storage,
            MemoryLocation::CpuToGpu,
        )?;
        let seed = Buffer::new(
            gpu,
            &format!("udlod seed tiles {i}"),
            UDLOD_SEED_TILES as u64 * TILE_BYTES,
            vk::BufferUsageFlags::TRANSFER_SRC,
            MemoryLocation::CpuToGpu,
        )?;
        let slot = SlotBuffers {
            uniforms,
            state,
            lists: TileLists::new(gpu, i, capacity)?,
            counters,
            field,
            field_key: None,
            seed,
            seed_tiles: 0,
            passes: 0,
            set,
            drawn: false,
        };
        slot.write_set(sets, i, min_max)?;
        Ok(slot)
    }

    pub(super) fn write_set(
        &self,
        sets: &DescriptorSets,
        i: usize,
        min_max: &Buffer,
    ) -> Result<()> {
        sets.write(
            i,
            &[
                ("udlod", Resource::Buffer(self.uniforms.raw)),
                ("state", Resource::Buffer(self.state.raw)),
                ("temp_tiles", Resource::Buffer(self.lists.temp.raw)),
                ("final_tiles", Resource::Buffer(self.lists.final_tiles.raw)),
                ("min_max", Resource::Buffer(min_max.raw)),
                ("split_field", Resource::Buffer(self.field.raw)),
            ],
        )
    }
}
