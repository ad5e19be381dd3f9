//! UDLOD (Kühnert): the quadtree is refined on the GPU in compute, one level per pass with
//! indirect dispatches, into a final tile list drawn with indexed indirect draws (one instance
//! per tile over a shared grid, one draw per draw mask: [`grid`]); vertices morph between
//! levels in the vertex shader. The coarse levels' few tiles are walked on the host instead
//! ([`seed`]), and the passes start below them.
//!
//! On the CPU, in the order the data flows: [`levels`] (the quadtree and its statistics),
//! [`field`] (per-tile split distances: the split field, uploaded), [`select`] (per-frame
//! parameters, culling and the reference selection the GPU's is tested against) and [`morph`]
//! (the vertex morph cascade, mirrored by `shaders/include/udlod_morph.wgsl`).
//!
//! CPU state ([`levels::Levels`]: per-tile min/max, per-level errors) is built once; its GPU
//! mirror is the `min_max` buffer. Per frame the host writes only [`UdlodUniforms`] (split
//! distances from the pixel error target, frustum planes) and the seed's tiles; the tile lists
//! never come back to the host in the render path (only the tiling state's counters, for
//! statistics).

pub mod completion;
pub mod field;
pub mod gpu;
pub mod grid;
pub mod levels;
pub mod morph;
pub mod params;
#[cfg(feature = "test-support")]
pub mod probe;
pub mod seed;
pub mod select;
pub mod settings;

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::{DrawnTiles, LodMethod, MethodContext};
use crate::dataset::stats::{FieldStats, TileStats};
use crate::dataset::{Level0, Terrain};
use crate::driver::Gpu;
use crate::driver::barrier::{Barriers, MemoryAccess};
use crate::driver::descriptors::DescriptorSets;
use crate::driver::device::Feature;
use crate::driver::memory::Buffer;
use crate::driver::pipeline::{Pipeline, TerrainPipelineDesc, compute_pipeline, terrain_pipeline};
use crate::error::{Error, Result};
use crate::frame::ViewState;
use crate::gpu_constants::{UDLOD_MAX_LEVELS, UDLOD_TILE_MASKS};
use crate::slots::ViewSlot;
use field::{FieldKey, SplitField};
pub use gpu::{
    DRAW_GROUPS, DRAW_STRIDE, DRAWS_OFFSET, MORPHING_DRAWS_OFFSET, STATIC_DRAWS_OFFSET, TILE_BYTES,
    TilingState, UDLOD_SET, UdlodUniforms, draw_group,
};
use gpu::{SlotBuffers, TileLists};
use grid::{QuadrantDraw, TileMask};
use levels::Levels;
use params::SelectionParams;
use settings::{BackFaces, LodMetric, UdlodSettings};

pub struct Udlod {
    gpu: Arc<Gpu>,
    settings: UdlodSettings,
    levels: Levels,
    /// Level-0 heights for the reference height under the LOD viewer (shared with the
    /// caller: the grid's `Arc`, or the pyramid reader with its bounded node cache).
    heights: Terrain,
    /// The geolocation lattice (None: the flat world), for the CPU reference's curved boxes.
    lattice: Option<Arc<crate::geo::Lattice>>,
    /// The build of the terrain shaders this terrain draws with (tests' morph probe too).
    #[cfg_attr(not(feature = "test-support"), allow(dead_code))]
    variant: crate::driver::shaders::TerrainVariant,
    /// The split field of the last key asked for (per-tile split distances).
    field: Option<Arc<SplitField>>,
    /// GPU mirror of `levels.min_max` (bound in every slot's set, written again when a slot's
    /// lists grow).
    min_max: Buffer,
    /// Every draw mask's index list ([`grid::IndexLayout`]).
    indices: Buffer,
    /// `UdlodUniforms::masks`.
    masks: [[u32; 4]; UDLOD_TILE_MASKS as usize],
    slots: Vec<SlotBuffers>,
    /// Set 1 of every slot (`SlotBuffers::set`).
    #[cfg_attr(not(feature = "test-support"), allow(dead_code))]
    sets: DescriptorSets,
    prepare: Pipeline,
    refine: Pipeline,
    finish: Pipeline,
    scatter: Pipeline,
    /// Draws the static groups (tiles with no vertex part-way through its morph), with
    /// back-face culling unless `back_faces = "none"`.
    draw: Pipeline,
    /// Draws the morphing groups, without it unless `back_faces = "all"`.
    draw_morphing: Pipeline,
    /// The most tiles a slot's lists grow to: `max_tiles`, at most the full tree's leaves.
    tile_cap: u32,
    /// The final-list capacity every slot grows to at its next frame: `initial_tiles` at
    /// first, doubled past a slot's capacity when a frame overflows it.
    wanted_tiles: u32,
}

/// `vkCmdDraw(Indexed)IndirectCount` and `vkCmdDraw(Indexed)Indirect` as ash takes them:
/// the indexed and non-indexed commands share their arguments (`Udlod::record_draws`).
type DrawIndirectCount = unsafe fn(
    &ash::Device,
    vk::CommandBuffer,
    vk::Buffer,
    vk::DeviceSize,
    vk::Buffer,
    vk::DeviceSize,
    u32,
    u32,
);
type DrawIndirect =
    unsafe fn(&ash::Device, vk::CommandBuffer, vk::Buffer, vk::DeviceSize, u32, u32);

impl Udlod {
    /// The quadtree's levels: tile statistics from a pyramid's stored ones (start-up reads no
    /// level 0), else computed from level 0 in parallel (the same bits either way); on the
    /// earth with `lod_metric = "axis"` the per-axis metric; a one-line error for a tree deeper
    /// than the shaders hold.
    fn build_levels(ctx: &MethodContext<'_>, settings: &UdlodSettings) -> Result<Levels> {
        // Without level 0's tiles: the tiling shader bounds them by their parents.
        let mut levels =
            Levels::from_field_stats(Self::field_stats(ctx.data, settings)?, ctx.data.spacing());
        debug_assert!(!levels.finest_held || levels.root_lod == 0);
        if let (Some(lattice), LodMetric::Axis) = (ctx.lattice, settings.lod_metric) {
            levels = levels.on_lattice(ctx.data.axis_spacing(), lattice);
        }
        // The morph reads the split distance one level past the root (never morphs).
        if levels.levels() >= UDLOD_MAX_LEVELS {
            return Err(Error::invalid(
                "udlod",
                format!(
                    "{} levels exceed the maximum of {}; raise grid_size",
                    levels.levels(),
                    UDLOD_MAX_LEVELS - 1
                ),
            ));
        }
        Ok(levels)
    }

    /// The statistics of the split field's cells (tiles of `grid_size / field_density` quads),
    /// from which the tiles' own follow bit for bit: a pyramid's stored ones, read without
    /// holding the cells' heights, else computed from level 0 in parallel.
    fn field_stats(data: &Terrain, settings: &UdlodSettings) -> Result<FieldStats> {
        let density = settings.field_density();
        let cell_quads = settings.grid_size / density;
        match data {
            Terrain::Grid(h) => {
                FieldStats::from_cells(TileStats::compute(&**h, cell_quads, &|_| {})?, density)
            }
            Terrain::Pyramid(p) => p.field_stats(cell_quads, density),
        }
    }

    /// The index buffer of every draw mask's triangles, and the masks' uniforms (with
    /// vertex pulling their vertex counts; the indices are not read).
    fn grid_indices(
        gpu: &Arc<Gpu>,
        grid_size: u32,
    ) -> Result<(Buffer, [[u32; 4]; UDLOD_TILE_MASKS as usize])> {
        let layout = grid::IndexLayout::new(grid_size);
        let index_bytes: &[u8] = bytemuck::cast_slice(&layout.indices);
        let indices = Buffer::with_data(
            gpu,
            "udlod grid indices",
            vk::BufferUsageFlags::INDEX_BUFFER,
            index_bytes,
        )?;
        Ok((
            indices,
            layout.ranges.map(|(first, count)| [count, first, 0, 0]),
        ))
    }

    /// The two draw pipelines: static and morphing tiles. By default the tiles with no vertex
    /// part-way through its morph with back-face culling, the others without (docs/udlod.md,
    /// "Pinholes far away and back faces").
    fn draw_pipelines(
        ctx: &MethodContext<'_>,
        settings: &UdlodSettings,
        set_layouts: &[vk::DescriptorSetLayout],
    ) -> Result<[Pipeline; 2]> {
        let entry = if settings.vertex_pulling {
            c"vs_pulled"
        } else {
            c"vs_main"
        };
        let cull_static = settings.back_faces != BackFaces::None;
        let cull_morphing = settings.back_faces == BackFaces::All;
        let pipeline = |cull_back_faces| {
            terrain_pipeline(
                ctx.gpu,
                &ctx.formats,
                &TerrainPipelineDesc {
                    spv: crate::driver::shaders::UDLOD_SPV.variant(ctx.terrain.variant),
                    vertex_entry: entry,
                    fragment_entry: c"fs_main",
                    set_layouts,
                    topology: vk::PrimitiveTopology::TRIANGLE_LIST,
                    cull_back_faces,
                },
            )
        };
        Ok([pipeline(cull_static)?, pipeline(cull_morphing)?])
    }

    pub fn new(ctx: &MethodContext<'_>, settings: &UdlodSettings) -> Result<Self> {
        let gpu = ctx.gpu;
        let settings = settings.clone();
        settings.validate()?;
        // Each draw's first instance is its group's first entry in the sorted list.
        gpu.require(Feature::DrawIndirectFirstInstance, "method udlod")?;
        let levels = Self::build_levels(ctx, &settings)?;
        let sets = DescriptorSets::new(gpu, UDLOD_SET, ctx.slots)?;
        let mm_bytes: &[u8] = bytemuck::cast_slice(&levels.min_max);
        let min_max = Buffer::with_data(
            gpu,
            "udlod min/max",
            vk::BufferUsageFlags::STORAGE_BUFFER,
            mm_bytes,
        )?;
        // The split field's nodes (a one-level tree has none, and a buffer is never empty).
        let field_bytes = (levels.field_nodes() as u64 * 4).max(4);
        let (indices, masks) = Self::grid_indices(gpu, settings.grid_size)?;

        // No selection reserves more leaves than the full tree over the root's square has
        // (4^root_lod), so small data sets do not allocate the whole budget.
        let full_tree = 1u64 << (2 * levels.root_lod).min(62);
        let tile_cap = (settings.max_tiles as u64).min(full_tree) as u32;
        // By default each frame's lists are sized before its prepass from a bound on what the
        // view can reserve (`update`), so they start with one tile; lists of `initial_tiles`
        // (the opt-in ablation) grow only when a frame overflows them (`grow_lists`).
        let first = if settings.initial_tiles > 0 {
            settings.initial_tiles
        } else {
            1
        }
        .min(tile_cap);
        let slots = (sets.sets.iter().enumerate())
            .map(|(i, &set)| SlotBuffers::new(gpu, &sets, (i, set), (first, field_bytes), &min_max))
            .collect::<Result<Vec<_>>>()?;
        let set_layouts = [ctx.terrain.descriptors.layout, sets.layout];
        let tiling = crate::driver::shaders::UDLOD_TILING_SPV.variant(ctx.terrain.variant);
        let prepare = compute_pipeline(gpu, tiling, c"prepare", &set_layouts)?;
        let refine = compute_pipeline(gpu, tiling, c"refine", &set_layouts)?;
        let finish = compute_pipeline(gpu, tiling, c"finish", &set_layouts)?;
        let scatter = compute_pipeline(gpu, tiling, c"scatter", &set_layouts)?;
        let [draw, draw_morphing] = Self::draw_pipelines(ctx, &settings, &set_layouts)?;
        Ok(Udlod {
            gpu: gpu.clone(),
            settings,
            heights: ctx.data.clone(),
            lattice: ctx.lattice.cloned(),
            variant: ctx.terrain.variant,
            levels,
            field: None,
            min_max,
            indices,
            masks,
            slots,
            sets,
            prepare,
            refine,
            finish,
            scatter,
            draw,
            draw_morphing,
            tile_cap,
            wanted_tiles: first,
        })
    }

    pub fn levels(&self) -> &Levels {
        &self.levels
    }

    /// The split field for `key`, built when the key changes (once per renderer and view
    /// size in practice). The field's cells' errors are held only while it is built: another
    /// key reads (or computes) them again, as at start-up (docs/udlod-rounds.md, "The finer field
    /// as the default").
    fn split_field(&mut self, key: FieldKey) -> Result<Arc<SplitField>> {
        if let Some(f) = self.field.as_ref().filter(|f| f.key == key) {
            return Ok(f.clone());
        }
        if !self.levels.holds_field_errors() {
            tracing::info!("udlod: a new split-field key; reading its cells' statistics again");
            let stats = Self::field_stats(&self.heights, &self.settings)?;
            self.levels.restore_field_errors(stats)?;
        }
        let f = Arc::new(SplitField::new(&self.levels, key));
        self.levels.release_field_errors();
        self.field = Some(f.clone());
        Ok(f)
    }

    /// The selection inputs for a view, exactly as uploaded (tests use them for the CPU
    /// reference).
    pub fn selection_params(&mut self, view: &ViewState) -> Result<SelectionParams> {
        let key = FieldKey::new(&self.settings, view.camera.focal_px(view.height));
        let field = self.split_field(key)?;
        let z_ref = match view.ground_m {
            Some(z) => z,
            None => self
                .heights
                .bilinear(view.lod_viewer.x, view.lod_viewer.y)?,
        };
        let p = SelectionParams::with_reference(
            &self.levels,
            field,
            z_ref,
            &self.settings,
            &view.camera,
            view.lod_viewer,
            view.width,
            view.height,
        );
        Ok(match &self.lattice {
            Some(l) => p.on_earth(&self.levels, l.clone(), view.camera.position),
            None => p,
        })
    }

    /// The GPU's final tile list of `slot`'s last completed frame as drawn, `[x, y, lod,
    /// group]` each ([`draw_group`]), sorted by group: the static tiles, then the morphing ones.
    fn final_tiles(&self, slot: ViewSlot) -> Result<Vec<[u32; 4]>> {
        let n: u64 = self.read_counters(slot).drawn().iter().sum();
        if n == 0 {
            return Ok(Vec::new());
        }
        let host = Buffer::new(
            &self.gpu,
            "udlod final tiles",
            n * TILE_BYTES,
            vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuToCpu,
        )?;
        let lists = &self.slots[slot.index()].lists;
        let b = Barriers::new(&self.gpu);
        self.gpu.one_shot(|cmd| {
            b.copy_for_host(
                cmd,
                MemoryAccess::PreviousFrame,
                (lists.final_tiles.raw, lists.capacity as u64 * TILE_BYTES),
                host.raw,
                n * TILE_BYTES,
            )
        })?;
        let bytes = host
            .mapped()
            .and_then(|b| b.get(..(n * TILE_BYTES) as usize))
            .ok_or_else(|| Error::invalid("udlod", "tile list readback not mapped"))?;
        Ok(bytemuck::pod_collect_to_vec(bytes))
    }

    /// The counters of `slot`'s last completed frame (zero before its first).
    fn read_counters(&self, slot: ViewSlot) -> TilingState {
        let s = &self.slots[slot.index()];
        s.counters
            .mapped()
            .filter(|_| s.drawn)
            .and_then(|bytes| bytes.get(..size_of::<TilingState>()))
            .map(bytemuck::pod_read_unaligned)
            .unwrap_or_default()
    }

    /// One pipeline's run of draws in `state` from `offset` (`UDLOD_TILE_MASKS` entries, the
    /// first `count_offset`'s count with tiles): with `drawIndirectCount` only those, else all
    /// in one call (`multiDrawIndirect`) or one call each. With vertex pulling `finish` wrote
    /// `VkDrawIndirectCommand`s in the same stride.
    fn record_draws(
        &self,
        cmd: vk::CommandBuffer,
        state: vk::Buffer,
        offset: u64,
        count_offset: u64,
    ) {
        let d = &self.gpu.device;
        let max = UDLOD_TILE_MASKS;
        let caps = &self.gpu.enabled;
        // Indexed draws, or with vertex pulling their non-indexed twins (same arguments).
        let (draw_count, draw): (DrawIndirectCount, DrawIndirect) = if self.settings.vertex_pulling
        {
            (
                ash::Device::cmd_draw_indirect_count,
                ash::Device::cmd_draw_indirect,
            )
        } else {
            (
                ash::Device::cmd_draw_indexed_indirect_count,
                ash::Device::cmd_draw_indexed_indirect,
            )
        };
        unsafe {
            if caps.draw_indirect_count {
                draw_count(d, cmd, state, offset, state, count_offset, max, DRAW_STRIDE);
                return;
            }
            let (calls, per_call) = if caps.multi_draw_indirect {
                (1, max)
            } else {
                (max, 1)
            };
            for call in 0..calls as u64 {
                let at = offset + call * DRAW_STRIDE as u64;
                draw(d, cmd, state, at, per_call, DRAW_STRIDE);
            }
        }
    }

    /// Grows `slot`'s tile lists, before its next frame, to `needed` tiles and past the
    /// capacity its last frame overflowed (doubled, or by twice the overflow), up to
    /// `max_tiles`. What one slot learns, every slot takes at its next frame. Returns the
    /// slot's capacity. The slot's previous frame has completed, so its old lists can go.
    fn grow_lists(&mut self, slot: ViewSlot, needed: u32) -> Result<u32> {
        let i = slot.index();
        let have = self.slots[i].lists.capacity;
        let overflow = self.read_counters(slot).overflow;
        let mut wanted = self.wanted_tiles.max(needed);
        if overflow > 0 {
            wanted = wanted.max(
                have.saturating_mul(2)
                    .max(have.saturating_add(overflow.saturating_mul(2))),
            );
        }
        self.wanted_tiles = wanted.min(self.tile_cap);
        if have < self.wanted_tiles {
            tracing::debug!(
                "udlod: slot {i}'s tile lists grow from {have} to {} tiles (overflow {overflow})",
                self.wanted_tiles
            );
            self.slots[i].lists = TileLists::new(&self.gpu, i, self.wanted_tiles)?;
            self.slots[i].write_set(&self.sets, i, &self.min_max)?;
        }
        Ok(self.slots[i].lists.capacity)
    }
}

impl LodMethod for Udlod {
    fn name(&self) -> &'static str {
        "udlod"
    }

    fn update(&mut self, slot: ViewSlot, view: &ViewState) -> Result<()> {
        let p = self.selection_params(view)?;
        let mut u = UdlodUniforms {
            frustum: p.frustum,
            ..Default::default()
        };
        for (i, (d, w)) in p.field.split.iter().zip(&p.field.zone).enumerate() {
            u.split[i] = [*d, *w, 0.0, 0.0];
        }
        for lod in 0..self.levels.levels() as usize {
            let (nx, ny) = self.levels.tiles_per_side[lod];
            u.levels[lod] = [
                self.levels.level_offsets[lod],
                nx,
                ny,
                p.field.corner_offsets[lod],
            ];
        }
        // What this view can reserve at most (flat world: with any viewer; on the earth the
        // frame's lowered stretch enters), so no frame overflows; 0 with `initial_tiles` set.
        let needed = if self.settings.initial_tiles == 0 {
            select::reserved_leaves_bound(&self.levels, &p.field, p.stretch)
                .min(self.tile_cap as u64) as u32
        } else {
            0
        };
        let capacity = self.grow_lists(slot, needed)?;
        u.sizes = [
            self.settings.grid_size,
            self.levels.root_lod,
            capacity,
            TileLists::temp_capacity(capacity),
        ];
        u.viewer = [p.viewer[0], p.viewer[1], p.viewer[2], 0.0];
        u.params = [
            if self.settings.collapse { 1.0 } else { 0.0 },
            p.morph_range,
            if p.morph { 1.0 } else { 0.0 },
            if p.cull { 1.0 } else { 0.0 },
        ];
        u.counts = [
            (p.cull && p.cull_quadrants) as u32,
            self.settings.dispatch_row,
            self.levels.field_density,
            self.settings.vertex_pulling as u32,
        ];
        u.masks = self.masks;
        u.metric = [p.stretch[0], p.stretch[1], 0.0, 0.0];
        let lists = seed::ListCapacity {
            final_tiles: capacity,
            temp_tiles: TileLists::temp_capacity(capacity),
        };
        let seed = seed::seed(&self.levels, &p, lists, self.settings.seed_tiles);
        u.seed = [seed.tiles.len() as u32, seed.requests, 0, 0];
        let s = &mut self.slots[slot.index()];
        // As the field: this slot's previous frame has completed.
        s.seed.write(bytemuck::cast_slice(&seed.tiles))?;
        s.seed_tiles = seed.tiles.len() as u32;
        s.passes = seed.passes;
        if s.field_key != Some(p.field.key) {
            // This slot's previous frame has completed (the renderer waits for a slot before
            // reusing it), so its copy may change.
            s.field.write(bytemuck::cast_slice(&p.field.corners))?;
            s.field_key = Some(p.field.key);
        }
        s.uniforms.write(bytemuck::bytes_of(&u))
    }

    fn record_prepass(
        &mut self,
        cmd: vk::CommandBuffer,
        slot: ViewSlot,
        frame_set: vk::DescriptorSet,
    ) {
        let gpu = &self.gpu;
        let d = &gpu.device;
        let b = Barriers::new(gpu);
        self.slots[slot.index()].drawn = true;
        let s = &self.slots[slot.index()];
        let sets = [frame_set, s.set];
        unsafe {
            // The buffers were last used by this slot's previous frame (same queue).
            b.memory(
                cmd,
                MemoryAccess::PreviousFrame,
                MemoryAccess::TransferWrite,
            );
            d.cmd_fill_buffer(cmd, s.state.raw, 0, vk::WHOLE_SIZE, 0);
            if s.seed_tiles > 0 {
                let seed = vk::BufferCopy {
                    src_offset: 0,
                    dst_offset: 0,
                    size: s.seed_tiles as u64 * TILE_BYTES,
                };
                d.cmd_copy_buffer(cmd, s.seed.raw, s.lists.temp.raw, &[seed]);
            }
            b.memory(
                cmd,
                MemoryAccess::TransferWrite,
                MemoryAccess::ComputeReadWrite,
            );
            b.memory(
                cmd,
                MemoryAccess::PreviousFrame,
                MemoryAccess::ComputeReadWrite,
            );
            d.cmd_bind_descriptor_sets(
                cmd,
                vk::PipelineBindPoint::COMPUTE,
                self.refine.layout,
                0,
                &sets,
                &[],
            );
            // One workgroup sizes the next dispatch in the state (`prepare`, `finish`), then
            // that indirect dispatch runs (`refine`, `scatter`), its writes read by `then`.
            let sized_pass = |sizing: &Pipeline, sized: &Pipeline, then: MemoryAccess| {
                d.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, sizing.raw);
                d.cmd_dispatch(cmd, 1, 1, 1);
                b.memory(cmd, MemoryAccess::ComputeWrite, MemoryAccess::IndirectRead);
                b.memory(
                    cmd,
                    MemoryAccess::ComputeWrite,
                    MemoryAccess::ComputeReadWrite,
                );
                d.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, sized.raw);
                d.cmd_dispatch_indirect(cmd, s.state.raw, 0);
                b.memory(cmd, MemoryAccess::ComputeWrite, then);
            };
            for _ in 0..s.passes {
                sized_pass(&self.prepare, &self.refine, MemoryAccess::ComputeReadWrite);
            }
            // The final tiles sorted by draw group into the list's second half.
            sized_pass(&self.finish, &self.scatter, MemoryAccess::VertexShaderRead);
            b.copy_for_host(
                cmd,
                MemoryAccess::ComputeWrite,
                (s.state.raw, 0),
                s.counters.raw,
                size_of::<TilingState>() as u64,
            );
        }
    }

    fn record_draw(
        &mut self,
        cmd: vk::CommandBuffer,
        slot: ViewSlot,
        frame_set: vk::DescriptorSet,
    ) {
        let d = &self.gpu.device;
        let s = &self.slots[slot.index()];
        let masks = UDLOD_TILE_MASKS;
        let group_bytes = masks as u64 * DRAW_STRIDE as u64;
        let runs = [
            (&self.draw, DRAWS_OFFSET, STATIC_DRAWS_OFFSET),
            (
                &self.draw_morphing,
                DRAWS_OFFSET + group_bytes,
                MORPHING_DRAWS_OFFSET,
            ),
        ];
        for (pipeline, offset, count_offset) in runs {
            unsafe {
                pipeline.bind(cmd, vk::PipelineBindPoint::GRAPHICS, &[frame_set, s.set]);
                if !self.settings.vertex_pulling {
                    d.cmd_bind_index_buffer(cmd, self.indices.raw, 0, vk::IndexType::UINT16);
                }
            }
            self.record_draws(cmd, s.state.raw, offset, count_offset);
        }
    }

    fn triangles(&self, slot: ViewSlot) -> u64 {
        let grid = self.settings.grid_size;
        let drawn = self.read_counters(slot).drawn();
        (drawn.iter().enumerate())
            .map(|(g, n)| n * grid::mask_triangles(grid, draw_group(g).0))
            .sum()
    }

    fn budget_overflow(&self, slot: ViewSlot) -> u64 {
        self.read_counters(slot).overflow as u64
    }

    fn tiles(&self, slot: ViewSlot) -> Option<u64> {
        Some(self.read_counters(slot).drawn().iter().sum())
    }

    fn counters(&self, slot: ViewSlot) -> Vec<(&'static str, u64)> {
        let c = self.read_counters(slot);
        let drawn = c.drawn();
        let sum = |f: &dyn Fn(TileMask, bool) -> u64| -> u64 {
            (drawn.iter().enumerate())
                .map(|(g, n)| {
                    let (mask, morphing) = draw_group(g);
                    n * f(mask, morphing)
                })
                .sum()
        };
        let all = grid::ALL_QUADRANTS;
        let collapsed = |m: TileMask| m.quadrants(QuadrantDraw::Collapsed);
        let dropped = |m: TileMask| m.quadrants(QuadrantDraw::Dropped);
        vec![
            ("tiles", drawn.iter().sum()),
            ("morphing", sum(&|_, morphing| morphing as u64)),
            // Tiles with a quadrant drawn as the parent grid, whole tiles drawn so, quadrants.
            ("collapsing", sum(&|m, _| (collapsed(m) != 0) as u64)),
            ("collapsed", sum(&|m, _| (collapsed(m) == all) as u64)),
            (
                "collapsed_quadrants",
                sum(&|m, _| collapsed(m).count_ones() as u64),
            ),
            // Quadrants of drawn tiles left out, outside the frustum.
            (
                "culled_quadrants",
                sum(&|m, _| dropped(m).count_ones() as u64),
            ),
            ("overflow", c.overflow as u64),
            ("culled", c.culled as u64),
            ("passes", c.passes_started as u64),
        ]
    }

    fn drawn_tiles(&self, slot: ViewSlot) -> Result<Option<DrawnTiles>> {
        Ok(Some(DrawnTiles {
            tiles: self
                .final_tiles(slot)?
                .iter()
                .map(|t| [t[0], t[1], t[2]])
                .collect(),
            tile_samples: self.settings.grid_size,
        }))
    }

    #[cfg(feature = "test-support")]
    fn debug_tiles(&self, slot: ViewSlot) -> Result<Option<Vec<[u32; 3]>>> {
        let tiles = self.final_tiles(slot)?;
        Ok(Some(tiles.iter().map(|t| [t[0], t[1], t[2]]).collect()))
    }

    #[cfg(feature = "test-support")]
    fn debug_tile_draws(&self, slot: ViewSlot) -> Result<Option<Vec<u32>>> {
        Ok(Some(self.final_tiles(slot)?.iter().map(|t| t[3]).collect()))
    }

    #[cfg(feature = "test-support")]
    fn probe_vertices(
        &self,
        slot: ViewSlot,
        frame: (vk::DescriptorSetLayout, vk::DescriptorSet),
        inputs: &[(levels::Tile, [u32; 2])],
    ) -> Result<Option<Vec<probe::ProbedVertex>>> {
        let udlod = (self.sets.layout, self.slots[slot.index()].set);
        probe::probe(&self.gpu, self.variant, frame, udlod, inputs).map(Some)
    }
}
