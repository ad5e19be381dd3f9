//! The evaluator's metrics on the GPU (`shaders/eval_metrics.wgsl`): a frame analysis stage
//! ([`GpuAnalysis`], a [`FrameAnalysis`]) recorded after each evaluated frame's terrain pass.
//! It copies the frame's colour and depth targets into storage buffers and measures every
//! pixel against the exact level-0 surface ([`reference::ReferenceSurface`]) and against the
//! reference frame of the same cameras; the host reads back histograms, sums and the swimming
//! observations: kilobytes per frame, never the frame.
//!
//! [`EvalShared`] is what every analysed renderer of one evaluation shares: the reference
//! surface, the reference frame's colour and depth (written by the reference renderer's
//! analysis, read by the variants' in the same frame), the tracked swim points, pipelines and
//! descriptor sets. The evaluator renders one frame at a time (frames in flight = 1) and frame
//! `k` of the reference before frame `k` of every variant; each analysis starts with a barrier
//! after all earlier work of the queue, so the shared buffers need no more synchronization.

pub mod layout;
pub mod reference;

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use ash::vk;
use crossbeam_channel::{Receiver, Sender, unbounded};
use gpu_allocator::MemoryLocation;

use self::layout::{EvalFrame, EvalView, PARTIAL_BYTES, Seed, Totals};
use self::reference::ReferenceSurface;
use super::metrics::{Histogram, Holes, SWIM_GRID, SWIM_SEED_EVERY};
use crate::dataset::{Level0, Terrain};
use crate::driver::Gpu;
use crate::driver::barrier::{Barriers, MemoryAccess};
use crate::driver::descriptors::{Binding, DescriptorSets, Resource};
use crate::driver::memory::Buffer;
use crate::driver::pipeline::{Pipeline, compute_pipeline};
use crate::error::{Error, Result};
use crate::geo::Lattice;
use crate::gpu_constants::{
    EVAL_HIST_BINS, EVAL_NO_ERROR_PX, EVAL_POINT_WORKGROUP, EVAL_REDUCE_WORKGROUP, EVAL_TILE_PX,
};
use crate::render::analysis::{AnalysisFrame, FrameAnalysis};
use crate::slots::FrameSlot;

/// The analysis' one descriptor set (`shaders/eval_metrics.wgsl`, every pass reads it).
pub const EVAL_SET: &[Binding] = {
    use vk::DescriptorType as T;
    const C: vk::ShaderStageFlags = vk::ShaderStageFlags::COMPUTE;
    &[
        Binding::new(0, T::UNIFORM_BUFFER, C, "frame"),
        // Level-0 reference tiles and the table of their slots.
        Binding::new(1, T::STORAGE_BUFFER, C, "ref_tiles"),
        Binding::new(2, T::STORAGE_BUFFER, C, "ref_table"),
        // The analysed frame and the reference frame of the same cameras.
        Binding::new(3, T::STORAGE_BUFFER, C, "depth"),
        Binding::new(4, T::STORAGE_BUFFER, C, "color"),
        Binding::new(5, T::STORAGE_BUFFER, C, "ref_depth"),
        Binding::new(6, T::STORAGE_BUFFER, C, "ref_color"),
        Binding::new(7, T::STORAGE_BUFFER, C, "seeds"),
        Binding::new(8, T::STORAGE_BUFFER, C, "error_image"),
        Binding::new(9, T::STORAGE_BUFFER, C, "partials"),
        Binding::new(10, T::STORAGE_BUFFER, C, "stats"),
        Binding::new(11, T::STORAGE_BUFFER, C, "metres_image"),
        // The renderer's geolocation lattice (a placeholder node in a flat world).
        Binding::new(12, T::STORAGE_BUFFER, C, "geo_lattice"),
    ]
};

const TOTALS_BYTES: u64 = size_of::<Totals>() as u64;

/// One partial per 8x8 block, and at least one per invocation of the fold pass (which
/// writes them all: shaders/eval_metrics.wgsl `fold_main`).
fn partials_bytes(groups: (u32, u32)) -> u64 {
    (groups.0 as u64 * groups.1 as u64).max(EVAL_REDUCE_WORKGROUP as u64) * PARTIAL_BYTES
}
const HIST_BYTES: u64 = 3 * EVAL_HIST_BINS as u64 * 4;

/// Frame size and views of an evaluation.
#[derive(Clone, Copy, Debug)]
pub struct FrameShape {
    pub width: u32,
    pub height: u32,
    pub views: usize,
}

/// What every analysed renderer of one evaluation shares (see the module docs).
pub struct EvalShared {
    gpu: Arc<Gpu>,
    /// Level 0 around the views; [`ReferenceSurface::prepare`] before each frame.
    pub surface: Mutex<ReferenceSurface>,
    atlas: vk::Buffer,
    table: vk::Buffer,
    ref_depth: Buffer,
    ref_color: Buffer,
    seeds: Buffer,
    /// Zeros copied over a run's statistics at the start of each frame.
    zeros: Buffer,
    sets: DescriptorSets,
    next_set: AtomicUsize,
    pixels: Pipeline,
    blocks: Pipeline,
    fold: Pipeline,
    reduce: Pipeline,
    seed: Pipeline,
    swim: Pipeline,
    pub shape: FrameShape,
    /// Frames of the evaluation (bounds the tracked points).
    pub frames: u64,
    spacing: f64,
    data_size: (u32, u32),
    /// Where the renderers place the terrain on the earth (None: the flat world); the shader
    /// maps each pixel's point back to the grid through it.
    lattice: Option<Lattice>,
    lattice_nodes: Buffer,
}

impl EvalShared {
    /// Shared state for `runs` analysed renderers of `frames` frames of `shape` over `data`,
    /// with a reference atlas of at most `reference_bytes`; `lattice`: the renderers' terrain
    /// on the earth (the lattice they were opened with), None: the flat world.
    pub fn new(
        gpu: &Arc<Gpu>,
        data: &Terrain,
        lattice: Option<&Lattice>,
        shape: FrameShape,
        frames: u64,
        runs: usize,
        reference_bytes: u64,
    ) -> Result<Arc<Self>> {
        let surface = ReferenceSurface::new(gpu, data, lattice, reference_bytes)?;
        let nodes = lattice.map_or_else(
            || vec![0.0; crate::geo::lattice::NODE_FLOATS],
            Lattice::gpu_nodes,
        );
        let lattice_nodes = Buffer::with_data(
            gpu,
            "eval geolocation lattice",
            vk::BufferUsageFlags::STORAGE_BUFFER,
            bytemuck::cast_slice(&nodes),
        )?;
        let pixels = shape.width as u64 * shape.height as u64;
        let storage = |name: &str, bytes: u64| {
            Buffer::new(
                gpu,
                name,
                bytes,
                vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_DST,
                MemoryLocation::GpuOnly,
            )
        };
        let max_points = max_points(frames);
        let stats = stats_bytes(max_points);
        let mut zeros = Buffer::new(
            gpu,
            "eval zeros",
            TOTALS_BYTES + HIST_BYTES,
            vk::BufferUsageFlags::TRANSFER_SRC,
            MemoryLocation::CpuToGpu,
        )?;
        zeros.write(&vec![0u8; (TOTALS_BYTES + HIST_BYTES) as usize])?;
        debug_assert!(stats >= TOTALS_BYTES + HIST_BYTES);
        let sets = DescriptorSets::new(gpu, EVAL_SET, runs.max(1))?;
        let spv = crate::driver::shaders::EVAL_METRICS_SPV;
        let layouts = [sets.layout];
        Ok(Arc::new(EvalShared {
            gpu: gpu.clone(),
            atlas: surface.atlas.raw,
            table: surface.table.raw,
            surface: Mutex::new(surface),
            ref_depth: storage("eval reference depth", pixels * 4)?,
            ref_color: storage("eval reference colour", pixels * 4)?,
            seeds: storage(
                "eval swim points",
                max_points as u64 * size_of::<Seed>() as u64,
            )?,
            zeros,
            pixels: compute_pipeline(gpu, spv, c"pixels_main", &layouts)?,
            blocks: compute_pipeline(gpu, spv, c"blocks_main", &layouts)?,
            fold: compute_pipeline(gpu, spv, c"fold_main", &layouts)?,
            reduce: compute_pipeline(gpu, spv, c"reduce_main", &layouts)?,
            seed: compute_pipeline(gpu, spv, c"seed_main", &layouts)?,
            swim: compute_pipeline(gpu, spv, c"swim_main", &layouts)?,
            sets,
            next_set: AtomicUsize::new(0),
            shape,
            frames,
            spacing: data.spacing(),
            data_size: (data.width(), data.height()),
            lattice: lattice.cloned(),
            lattice_nodes,
        }))
    }

    /// The renderers' geolocation lattice (None: the flat world).
    pub fn lattice(&self) -> Option<&Lattice> {
        self.lattice.as_ref()
    }

    /// Readies the reference surface for frame `frame` of `views` (no frame in flight).
    pub fn prepare(&self, frame: u64, views: &[reference::ViewCone]) -> Result<()> {
        self.surface
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .prepare(frame, views)
    }
}

/// Tracked swim points of an evaluation of `frames` frames (a grid of seeds every
/// [`SWIM_SEED_EVERY`] frames).
fn max_points(frames: u64) -> u32 {
    (frames.div_ceil(SWIM_SEED_EVERY) * (SWIM_GRID.0 * SWIM_GRID.1) as u64) as u32
}

fn stats_bytes(points: u32) -> u64 {
    TOTALS_BYTES + HIST_BYTES + points.max(1) as u64 * 8
}

/// Whether an analysed renderer draws the reference (its frame is what the others compare
/// their images with, and it seeds the swim points) or a variant.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    Reference,
    Variant,
}

/// The measurements of one frame, read back from the GPU.
#[derive(Clone, Debug)]
pub struct GpuFrameMetrics {
    pub index: u64,
    /// |height error| (m) and screen-space error (px) of every pixel measured.
    pub metres: Histogram,
    pub pixels: Histogram,
    /// Popping against the previous frame (px; empty for the first frame).
    pub popping: Histogram,
    pub holes: Holes,
    /// Sum of squared RGB differences to the reference frame, over `3 * pixels` channels.
    pub squared_error_sum: u64,
    pub channels: u64,
    pub ssim_sum: f64,
    pub ssim_windows: u64,
    /// Per tracked point (seed order): the height error (m) and distance (m) where this frame
    /// shows it.
    pub swim: Vec<Option<(f64, f64)>>,
    /// Pixels and points without a reference tile (0 unless the tile selection is wrong).
    pub missing_reference: u32,
    /// The signed screen-space error per pixel (image frames only).
    pub error_image: Option<Vec<f32>>,
}

impl GpuFrameMetrics {
    /// PSNR in dB over RGB (infinite when identical), as [`super::metrics::psnr`].
    pub fn psnr_db(&self) -> f64 {
        super::metrics::psnr_of(self.squared_error_sum as f64, self.channels)
    }

    /// Mean SSIM over the 8x8 windows, as [`super::metrics::ssim`].
    pub fn ssim(&self) -> f64 {
        if self.ssim_windows == 0 {
            1.0
        } else {
            self.ssim_sum / self.ssim_windows as f64
        }
    }
}

impl FrameShape {
    /// 8x8 blocks per row and column of the frame (one SSIM window and partial sum each).
    fn block_groups(&self) -> (u32, u32) {
        (
            self.width.div_ceil(EVAL_TILE_PX),
            self.height.div_ceil(EVAL_TILE_PX),
        )
    }

    /// Workgroups of the per-pixel pass: the widest view's columns, rows, views.
    fn pixel_groups(&self) -> (u32, u32, u32) {
        let widest = (0..self.views)
            .map(|v| crate::render::view_columns(self.width, self.views, v).1)
            .max()
            .unwrap_or(self.width);
        (
            widest.div_ceil(EVAL_TILE_PX),
            self.height.div_ceil(EVAL_TILE_PX),
            self.views.max(1) as u32,
        )
    }
}

/// A storage buffer in device memory for the analysis' passes (`usage` besides storage).
fn device_buffer(
    gpu: &Arc<Gpu>,
    name: &str,
    bytes: u64,
    usage: vk::BufferUsageFlags,
) -> Result<Buffer> {
    Buffer::new(
        gpu,
        name,
        bytes,
        vk::BufferUsageFlags::STORAGE_BUFFER | usage,
        MemoryLocation::GpuOnly,
    )
}

/// A buffer the host reads back, filled by a copy.
fn host_buffer(gpu: &Arc<Gpu>, name: &str, bytes: u64) -> Result<Buffer> {
    Buffer::new(
        gpu,
        name,
        bytes,
        vk::BufferUsageFlags::TRANSFER_DST,
        MemoryLocation::GpuToCpu,
    )
}

/// The buffers one analysis owns, before they become [`GpuAnalysis`]'s fields.
struct AnalysisBuffers {
    uniform: Buffer,
    /// The variant's own copies of its targets (the reference writes the shared ones).
    own: Option<(Buffer, Buffer)>,
    depth: vk::Buffer,
    color: vk::Buffer,
    error_image: Buffer,
    metres_image: Buffer,
    partials: Buffer,
    stats: Buffer,
    stats_host: Buffer,
    /// Where the error images are read back, when any frame's is wanted.
    export: Option<Buffer>,
}

impl AnalysisBuffers {
    fn new(
        shared: &EvalShared,
        role: Role,
        groups: (u32, u32),
        export_images: bool,
    ) -> Result<Self> {
        let gpu = &shared.gpu;
        let pixels = shared.shape.width as u64 * shared.shape.height as u64;
        let own = match role {
            Role::Reference => None,
            Role::Variant => Some((
                device_buffer(
                    gpu,
                    "eval depth",
                    pixels * 4,
                    vk::BufferUsageFlags::TRANSFER_DST,
                )?,
                device_buffer(
                    gpu,
                    "eval colour",
                    pixels * 4,
                    vk::BufferUsageFlags::TRANSFER_DST,
                )?,
            )),
        };
        let (depth, color) = match &own {
            Some((d, c)) => (d.raw, c.raw),
            None => (shared.ref_depth.raw, shared.ref_color.raw),
        };
        let copy_usage = vk::BufferUsageFlags::TRANSFER_DST | vk::BufferUsageFlags::TRANSFER_SRC;
        let none = vk::BufferUsageFlags::empty();
        let error_image = device_buffer(gpu, "eval error image", pixels * 4, copy_usage)?;
        let metres_image = device_buffer(gpu, "eval height error image", pixels * 4, none)?;
        let partials = device_buffer(gpu, "eval partials", partials_bytes(groups), none)?;
        let stats_size = stats_bytes(max_points(shared.frames));
        let stats = device_buffer(gpu, "eval statistics", stats_size, copy_usage)?;
        let stats_host = host_buffer(gpu, "eval statistics (host)", stats_size)?;
        let export = if export_images {
            Some(host_buffer(gpu, "eval error image (host)", pixels * 4)?)
        } else {
            None
        };
        let uniform = Buffer::new(
            gpu,
            "eval frame uniforms",
            size_of::<EvalFrame>() as u64,
            vk::BufferUsageFlags::UNIFORM_BUFFER,
            MemoryLocation::CpuToGpu,
        )?;
        Ok(AnalysisBuffers {
            uniform,
            own,
            depth,
            color,
            error_image,
            metres_image,
            partials,
            stats,
            stats_host,
            export,
        })
    }

    /// Fills the error image with [`EVAL_NO_ERROR_PX`], the value of a pixel without an error
    /// (sky, or off the data), which the shader expects before the first frame.
    fn clear_error_image(&self, gpu: &Gpu) -> Result<()> {
        let no_error = EVAL_NO_ERROR_PX.to_bits();
        let image = self.error_image.raw;
        gpu.one_shot(|cmd| unsafe {
            gpu.device
                .cmd_fill_buffer(cmd, image, 0, vk::WHOLE_SIZE, no_error)
        })
    }

    /// Points descriptor set `index` of `shared` at these buffers and the shared ones.
    fn bind(&self, shared: &EvalShared, index: usize) -> Result<()> {
        let buffer = Resource::Buffer;
        shared.sets.write(
            index,
            &[
                ("frame", buffer(self.uniform.raw)),
                ("ref_tiles", buffer(shared.atlas)),
                ("ref_table", buffer(shared.table)),
                ("depth", buffer(self.depth)),
                ("color", buffer(self.color)),
                ("ref_depth", buffer(shared.ref_depth.raw)),
                ("ref_color", buffer(shared.ref_color.raw)),
                ("seeds", buffer(shared.seeds.raw)),
                ("error_image", buffer(self.error_image.raw)),
                ("partials", buffer(self.partials.raw)),
                ("stats", buffer(self.stats.raw)),
                ("metres_image", buffer(self.metres_image.raw)),
                ("geo_lattice", buffer(shared.lattice_nodes.raw)),
            ],
        )
    }
}

/// One renderer's frame analysis (see the module docs).
pub struct GpuAnalysis {
    shared: Arc<EvalShared>,
    role: Role,
    set: vk::DescriptorSet,
    uniform: Buffer,
    /// The variant's own copies of its targets (the reference writes the shared ones).
    _own: Option<(Buffer, Buffer)>,
    depth: vk::Buffer,
    color: vk::Buffer,
    error_image: Buffer,
    _metres_image: Buffer,
    _partials: Buffer,
    stats: Buffer,
    stats_host: Buffer,
    export: Option<Buffer>,
    image_frames: Vec<u64>,
    /// 8x8 blocks per row and column of the frame (one SSIM window and partial sum each).
    groups: (u32, u32),
    /// Workgroups of the per-pixel pass: the widest view's columns, rows, views.
    pixel_groups: (u32, u32, u32),
    recorded: u64,
    results: Sender<GpuFrameMetrics>,
}

impl GpuAnalysis {
    /// The analysis of one renderer of `shared`'s evaluation; the error images of
    /// `image_frames` are read back too. Each frame's results arrive on the returned receiver
    /// when the renderer delivers the frame.
    pub fn new(
        shared: &Arc<EvalShared>,
        role: Role,
        image_frames: Vec<u64>,
    ) -> Result<(Self, Receiver<GpuFrameMetrics>)> {
        let (results, receiver) = unbounded();
        let index = shared.next_set.fetch_add(1, Ordering::Relaxed);
        let set = *shared.sets.sets.get(index).ok_or_else(|| {
            Error::invalid(
                "eval",
                "more analysed renderers than the evaluation planned",
            )
        })?;
        let groups = shared.shape.block_groups();
        let b = AnalysisBuffers::new(shared, role, groups, !image_frames.is_empty())?;
        b.clear_error_image(&shared.gpu)?;
        b.bind(shared, index)?;
        let analysis = GpuAnalysis {
            shared: shared.clone(),
            role,
            set,
            uniform: b.uniform,
            _own: b.own,
            depth: b.depth,
            color: b.color,
            error_image: b.error_image,
            _metres_image: b.metres_image,
            _partials: b.partials,
            stats: b.stats,
            stats_host: b.stats_host,
            export: b.export,
            image_frames,
            groups,
            pixel_groups: shared.shape.pixel_groups(),
            recorded: 0,
            results,
        };
        Ok((analysis, receiver))
    }

    /// The uniforms of frame `frame`.
    fn uniforms(&self, frame: &AnalysisFrame<'_>) -> Result<EvalFrame> {
        let shape = self.shared.shape;
        if frame.cameras.len() != shape.views || frame.columns.len() != shape.views {
            return Err(Error::invalid(
                "eval",
                format!(
                    "{} cameras for an analysis of {} views",
                    frame.cameras.len(),
                    shape.views
                ),
            ));
        }
        if frame.index >= self.shared.frames {
            return Err(Error::invalid(
                "eval",
                format!(
                    "frame {} of an evaluation of {} frames",
                    frame.index, self.shared.frames
                ),
            ));
        }
        let mut views = [EvalView::default(); crate::gpu_constants::EVAL_MAX_VIEWS as usize];
        for (v, (camera, &columns)) in frame.cameras.iter().zip(frame.columns).enumerate() {
            views[v] = EvalView::new(
                camera,
                columns,
                shape.height,
                self.shared.spacing,
                self.shared.lattice.as_ref(),
            );
        }
        let grid = SWIM_GRID.0 * SWIM_GRID.1;
        let round = (frame.index / SWIM_SEED_EVERY) as u32;
        let seeding = self.role == Role::Reference && frame.index % SWIM_SEED_EVERY == 0;
        let (tx, ty) = self
            .shared
            .surface
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .tiles();
        Ok(EvalFrame {
            views,
            size: [
                shape.width,
                shape.height,
                shape.views as u32,
                u32::from(self.recorded > 0),
            ],
            data: [self.shared.data_size.0, self.shared.data_size.1, tx, ty],
            params: [self.shared.spacing as f32, 0.0, 0.0, 0.0],
            points: [
                (round + 1) * grid,
                round * grid,
                if seeding { grid } else { 0 },
                self.groups.0 * self.groups.1,
            ],
            grid: [SWIM_GRID.0, SWIM_GRID.1, self.groups.0, 0],
            lattice: self
                .shared
                .lattice
                .as_ref()
                .map_or([0; 4], |l| [l.step, l.nodes[0], l.nodes[1], 0]),
        })
    }

    /// Copies the frame's targets into the storage buffers the shader reads.
    fn record_copies(&self, cmd: vk::CommandBuffer, frame: &AnalysisFrame<'_>) {
        let t = frame.targets;
        let region = |aspect| {
            [vk::BufferImageCopy::default()
                .image_subresource(vk::ImageSubresourceLayers {
                    aspect_mask: aspect,
                    mip_level: 0,
                    base_array_layer: 0,
                    layer_count: 1,
                })
                .image_extent(vk::Extent3D {
                    width: t.extent.width,
                    height: t.extent.height,
                    depth: 1,
                })]
        };
        let d = &self.shared.gpu.device;
        let layout = vk::ImageLayout::TRANSFER_SRC_OPTIMAL;
        unsafe {
            d.cmd_copy_image_to_buffer(
                cmd,
                t.color.raw,
                layout,
                self.color,
                &region(vk::ImageAspectFlags::COLOR),
            );
            d.cmd_copy_image_to_buffer(
                cmd,
                t.depth.raw,
                layout,
                self.depth,
                &region(vk::ImageAspectFlags::DEPTH),
            );
            d.cmd_copy_buffer(
                cmd,
                self.shared.zeros.raw,
                self.stats.raw,
                &[vk::BufferCopy {
                    src_offset: 0,
                    dst_offset: 0,
                    size: TOTALS_BYTES + HIST_BYTES,
                }],
            );
        }
    }

    fn dispatch(&self, cmd: vk::CommandBuffer, pipeline: &Pipeline, groups: (u32, u32, u32)) {
        let d = &self.shared.gpu.device;
        unsafe {
            pipeline.bind(cmd, vk::PipelineBindPoint::COMPUTE, &[self.set]);
            d.cmd_dispatch(cmd, groups.0, groups.1, groups.2);
        }
    }

    /// Refuses a frame whose size is not the one this analysis was made for.
    fn check_extent(&self, frame: &AnalysisFrame<'_>) -> Result<()> {
        let shape = self.shared.shape;
        let extent = frame.targets.extent;
        if (extent.width, extent.height) != (shape.width, shape.height) {
            return Err(Error::invalid(
                "eval",
                format!(
                    "a {}x{} frame for an analysis of {}x{}",
                    extent.width, extent.height, shape.width, shape.height
                ),
            ));
        }
        Ok(())
    }

    /// The compute passes over the copied targets, each after the writes of those before it:
    /// the new tracked points (when `uniforms` seeds any), per pixel and per tracked point, per
    /// 8x8 block, then the fold and the reduction into the statistics.
    fn record_passes(&self, cmd: vk::CommandBuffer, b: &Barriers<'_>, uniforms: &EvalFrame) {
        let s = &self.shared;
        let seeds = uniforms.points[2];
        if seeds > 0 {
            self.dispatch(cmd, &s.seed, (seeds.div_ceil(EVAL_POINT_WORKGROUP), 1, 1));
            b.memory(
                cmd,
                MemoryAccess::ComputeWrite,
                MemoryAccess::ComputeReadWrite,
            );
        }
        self.dispatch(cmd, &s.pixels, self.pixel_groups);
        let points = uniforms.points[0];
        self.dispatch(cmd, &s.swim, (points.div_ceil(EVAL_POINT_WORKGROUP), 1, 1));
        b.memory(
            cmd,
            MemoryAccess::ComputeWrite,
            MemoryAccess::ComputeReadWrite,
        );
        let blocks = self.groups.0 * self.groups.1;
        self.dispatch(
            cmd,
            &s.blocks,
            (blocks.div_ceil(EVAL_POINT_WORKGROUP), 1, 1),
        );
        b.memory(
            cmd,
            MemoryAccess::ComputeWrite,
            MemoryAccess::ComputeReadWrite,
        );
        // Two passes without workgroup barriers (shaders/eval_metrics.wgsl `fold_main`).
        self.dispatch(cmd, &s.fold, (1, 1, 1));
        b.memory(
            cmd,
            MemoryAccess::ComputeWrite,
            MemoryAccess::ComputeReadWrite,
        );
        self.dispatch(cmd, &s.reduce, (1, 1, 1));
    }

    /// Copies the statistics (totals, histogram and the `points` tracked points) into the
    /// host's buffer and, on the frames whose error images are kept, the error image into the
    /// export buffer.
    fn record_readback(&self, cmd: vk::CommandBuffer, frame: &AnalysisFrame<'_>, points: u32) {
        let d = &self.shared.gpu.device;
        let bytes = TOTALS_BYTES + HIST_BYTES + points as u64 * 8;
        unsafe {
            d.cmd_copy_buffer(
                cmd,
                self.stats.raw,
                self.stats_host.raw,
                &[vk::BufferCopy {
                    src_offset: 0,
                    dst_offset: 0,
                    size: bytes,
                }],
            );
            if let Some(export) = &self.export
                && self.image_frames.contains(&frame.index)
            {
                d.cmd_copy_buffer(
                    cmd,
                    self.error_image.raw,
                    export.raw,
                    &[vk::BufferCopy {
                        src_offset: 0,
                        dst_offset: 0,
                        size: export.size,
                    }],
                );
            }
        }
    }
}

impl FrameAnalysis for GpuAnalysis {
    fn record(&mut self, cmd: vk::CommandBuffer, frame: &AnalysisFrame<'_>) -> Result<()> {
        self.check_extent(frame)?;
        let uniforms = self.uniforms(frame)?;
        self.uniform.write(bytemuck::bytes_of(&uniforms))?;
        let gpu = &self.shared.gpu;
        let b = Barriers::new(gpu);
        // After everything earlier in the queue: other renderers' analyses read and write the
        // shared buffers, this renderer's previous frame its own.
        b.memory(
            cmd,
            MemoryAccess::PreviousFrame,
            MemoryAccess::TransferWrite,
        );
        b.memory(
            cmd,
            MemoryAccess::PreviousFrame,
            MemoryAccess::ComputeReadWrite,
        );
        self.record_copies(cmd, frame);
        b.memory(
            cmd,
            MemoryAccess::TransferWrite,
            MemoryAccess::ComputeReadWrite,
        );
        self.record_passes(cmd, &b, &uniforms);
        b.memory(cmd, MemoryAccess::ComputeWrite, MemoryAccess::TransferRead);
        self.record_readback(cmd, frame, uniforms.points[0]);
        b.memory(cmd, MemoryAccess::TransferWrite, MemoryAccess::HostRead);
        self.recorded += 1;
        Ok(())
    }

    fn complete(&mut self, _slot: FrameSlot, index: u64) -> Result<()> {
        let bytes = self
            .stats_host
            .mapped()
            .ok_or_else(|| Error::invalid("eval", "statistics buffer not mapped"))?;
        let totals: Totals = bytemuck::pod_read_unaligned(&bytes[..TOTALS_BYTES as usize]);
        let words: &[u32] = bytemuck::cast_slice(
            &bytes[TOTALS_BYTES as usize..(TOTALS_BYTES + HIST_BYTES) as usize],
        );
        let bins = EVAL_HIST_BINS as usize;
        let points = ((index / SWIM_SEED_EVERY + 1) * (SWIM_GRID.0 * SWIM_GRID.1) as u64) as usize;
        let start = (TOTALS_BYTES + HIST_BYTES) as usize;
        let swim: &[f32] = bytemuck::cast_slice(&bytes[start..start + points * 8]);
        let shape = self.shared.shape;
        let count = totals.error_count as u64;
        let metrics = GpuFrameMetrics {
            index,
            metres: Histogram::from_bins(
                &words[..bins],
                count,
                totals.metres_sum as f64,
                Some(totals.metres_max as f64),
            ),
            pixels: Histogram::from_bins(
                &words[bins..2 * bins],
                count,
                totals.pixels_sum as f64,
                Some(totals.pixels_max as f64),
            ),
            // Every popping value is one count in its histogram.
            popping: Histogram::from_bins(
                &words[2 * bins..],
                words[2 * bins..].iter().map(|&c| c as u64).sum(),
                0.0,
                None,
            ),
            holes: Holes {
                all: totals.holes as usize,
                cracks: totals.cracks as usize,
                silhouette_px: totals.silhouette_px as u32,
            },
            squared_error_sum: totals.sq_lo as u64 | (totals.sq_hi as u64) << 32,
            channels: 3 * shape.width as u64 * shape.height as u64,
            ssim_sum: totals.ssim_sum as f64,
            ssim_windows: totals.ssim_windows as u64,
            swim: swim
                .chunks_exact(2)
                .map(|o| (o[1] >= 0.0).then_some((o[0] as f64, o[1] as f64)))
                .collect(),
            missing_reference: totals.missing,
            error_image: match &self.export {
                Some(e) if self.image_frames.contains(&index) => Some(
                    bytemuck::cast_slice(
                        e.mapped()
                            .ok_or_else(|| Error::invalid("eval", "error image not mapped"))?,
                    )
                    .to_vec(),
                ),
                _ => None,
            },
        };
        // The receiver outlives the renderer; a closed channel only drops this frame.
        let _ = self.results.send(metrics);
        Ok(())
    }
}
