//! The render loop: N frames in flight, each slot with its own command buffer, targets,
//! readback buffers and timestamp queries, ordered by one timeline semaphore.
//!
//! Frame `k` uses slot `k % N` and signals timeline value `k + 1`. After submitting frame `k`
//! the host delivers frame `k - (N - 1)` (waiting for its value only), so with N >= 2 the host
//! reads frame `k - 1` while the GPU works on frame `k`: it never waits on newer work.

pub mod pipeline;
pub mod stats;
pub mod terrain;

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::{Duration, Instant};

use ash::vk;
use gpu_allocator::MemoryLocation;

use crate::clipmap::Clipmap;
use crate::clipmap::gpu::ClipmapGpu;
use crate::dataset::{Level0, Terrain};
use crate::driver::Gpu;
use crate::driver::barrier::{Barriers, ImageAccess, MemoryAccess, color_range, depth_range};
use crate::driver::memory::{Buffer, Image, ImageDesc};
use crate::driver::sync::Timeline;
use crate::error::{Error, Result, VkResultExt};
use crate::lod::{LodMethod, MethodContext, MethodKind, ViewState};
use crate::readback::{DirectTarget, FrameSink, FrameTimings, FrameView};
use crate::scene::Camera;
use pipeline::{COLOR_FORMAT, DEPTH_FORMAT, TargetFormats};
use stats::RunStats;
use terrain::{FrameUniforms, TerrainGpu};

/// How long the host waits for one frame before calling the GPU hung.
const FRAME_TIMEOUT: Duration = Duration::from_secs(60);

/// Timestamps per slot: start, after prepass, after terrain pass, after readback copy.
const TIMESTAMPS: u32 = 4;

/// Most views (cameras) drawn into one frame.
pub const MAX_VIEWS: usize = 4;

/// Render-target and loop settings.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    pub width: u32,
    pub height: u32,
    pub frames_in_flight: usize,
    pub readback_depth: bool,
    /// Linear RGB of the sky (clear colour).
    pub sky: [f32; 3],
    /// Unit vector towards the sun.
    pub sun_dir: [f32; 3],
    /// LOD method settings.
    pub lod: crate::lod::LodSettings,
    /// Cameras per frame (1..=[`MAX_VIEWS`]), side by side: view `v` covers columns
    /// `v * width / views .. (v + 1) * width / views` ([`Renderer::view_columns`]).
    pub views: usize,
}

impl RenderOptions {
    pub fn from_config(config: &crate::config::Config) -> Self {
        let r = &config.render;
        let (az, el) = (
            r.sun_azimuth_deg.to_radians(),
            r.sun_elevation_deg.to_radians(),
        );
        RenderOptions {
            width: r.width,
            height: r.height,
            frames_in_flight: r.frames_in_flight as usize,
            readback_depth: r.readback_depth,
            sky: r.sky,
            sun_dir: [az.sin() * el.cos(), az.cos() * el.cos(), el.sin()],
            lod: config.lod.clone(),
            views: 1 + r.extra_views.len(),
        }
    }
}

/// One frame to render.
#[derive(Clone, Copy, Debug)]
pub struct FrameRequest {
    pub camera: Camera,
    /// Clear colour for this frame only (linear RGB); the configured sky otherwise.
    pub sky: Option<[f32; 3]>,
    /// Where LOD methods measure distances from, if not the camera (tests use it to watch one
    /// method's surface change from a fixed viewpoint while its LOD viewer moves).
    pub lod_viewer: Option<glam::DVec3>,
}

impl FrameRequest {
    /// The requests of one frame: `main` and a camera per offset (config
    /// `render.extra_views`), in view order.
    pub fn with_extra_views(main: Camera, extra: &[crate::scene::ViewOffset]) -> Vec<Self> {
        std::iter::once(main)
            .chain(extra.iter().map(|o| o.apply(&main)))
            .map(FrameRequest::from)
            .collect()
    }
}

impl From<Camera> for FrameRequest {
    fn from(camera: Camera) -> Self {
        FrameRequest {
            camera,
            sky: None,
            lod_viewer: None,
        }
    }
}

struct Pending {
    index: u64,
    camera: Camera,
    cpu_record_ms: f64,
    triangles: u64,
    /// Where the colour went when the sink asked for zero-copy ([`FrameSink::direct_target`]).
    direct: Option<DirectTarget>,
}

struct Slot {
    gpu: Arc<Gpu>,
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    color: Image,
    depth: Image,
    framebuffer: vk::Framebuffer,
    readback_color: Buffer,
    readback_depth: Option<Buffer>,
    queries: vk::QueryPool,
    pending: Option<Pending>,
}

impl Drop for Slot {
    fn drop(&mut self) {
        unsafe {
            let d = &self.gpu.device;
            d.destroy_query_pool(self.queries, None);
            if self.framebuffer != vk::Framebuffer::null() {
                d.destroy_framebuffer(self.framebuffer, None);
            }
            d.destroy_command_pool(self.pool, None);
        }
    }
}

/// Where the readback buffers live.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum ReadbackPath {
    /// Device-local *and* host-visible memory (unified memory: Jetson, lavapipe): the copy
    /// lands where the host reads it, no staging and no bus transfer.
    Unified,
    /// Host-visible system memory written by the GPU over the bus (discrete GPUs).
    HostStaging,
}

pub struct Renderer {
    gpu: Arc<Gpu>,
    pub options: RenderOptions,
    // Field order is drop order: slots and method hold GPU objects that reference `terrain`'s
    // layouts; the render pass goes last (see Drop).
    slots: Vec<Slot>,
    method: Box<dyn LodMethod>,
    terrain: TerrainGpu,
    clipmap: Option<Clipmap>,
    clipmap_gpu: ClipmapGpu,
    formats: TargetFormats,
    timeline: Timeline,
    timestamps: bool,
    next_frame: u64,
    in_flight: VecDeque<usize>,
    pub readback_path: ReadbackPath,
    pub stats: RunStats,
}

impl Renderer {
    /// `data`: an `Arc<Heightmap>` (or a `Terrain`) is shared; a `&Heightmap` is copied.
    pub fn new(
        gpu: &Arc<Gpu>,
        data: impl Into<Terrain>,
        method: MethodKind,
        options: RenderOptions,
    ) -> Result<Self> {
        Self::with_clipmap(gpu, data, method, options, None)
    }

    /// [`Renderer::new`] with heights, normals and albedo sampled through `clipmap` (its level
    /// 0 must be `data`'s; with a clipmap, `data` may be a [`Terrain::Pyramid`], whose level 0
    /// is never held whole on the host).
    pub fn with_clipmap(
        gpu: &Arc<Gpu>,
        data: impl Into<Terrain>,
        method: MethodKind,
        options: RenderOptions,
        clipmap: Option<Clipmap>,
    ) -> Result<Self> {
        let data: Terrain = data.into();
        let limits = &gpu.info.limits;
        if options.width == 0
            || options.height == 0
            || options.width > limits.max_framebuffer_width
            || options.height > limits.max_framebuffer_height
        {
            return Err(Error::invalid(
                "resolution",
                format!(
                    "{}x{} is outside 1..={}x{} (device limit)",
                    options.width,
                    options.height,
                    limits.max_framebuffer_width,
                    limits.max_framebuffer_height
                ),
            ));
        }
        if !(1..=8).contains(&options.frames_in_flight) {
            return Err(Error::invalid(
                "frames_in_flight",
                format!("{} is outside 1..=8", options.frames_in_flight),
            ));
        }
        let n = options.frames_in_flight;
        let views = options.views;
        if !(1..=MAX_VIEWS).contains(&views) || views as u32 > options.width {
            return Err(Error::invalid(
                "views",
                format!("{views} views per frame: need 1..={MAX_VIEWS} and at most one per column"),
            ));
        }
        if let Some(c) = &clipmap
            && c.views.len() != views
        {
            return Err(Error::invalid(
                "clipmap",
                format!(
                    "made for {} views but the renderer draws {views}",
                    c.views.len()
                ),
            ));
        }
        if let Some(c) = &clipmap
            && (c.geometry.width, c.geometry.height) != (data.width() as u64, data.height() as u64)
        {
            return Err(Error::invalid(
                "clipmap",
                format!(
                    "level 0 is {}x{} but the height map is {}x{} (use the data set's level 0)",
                    c.geometry.width,
                    c.geometry.height,
                    data.width(),
                    data.height()
                ),
            ));
        }
        let clipmap_gpu = match &clipmap {
            Some(c) => ClipmapGpu::new(
                gpu,
                Some(&c.geometry),
                &c.settings,
                c.settings.node_count,
                n,
                views,
            )?,
            None => ClipmapGpu::new(gpu, None, &Default::default(), 2, n, views)?,
        };
        // Per-view state (uniforms, set 0, the method's buffers, the clipmap's quadtree) lives
        // in view slots `frame slot * views + view`; targets and staging stay per frame slot.
        let terrain = TerrainGpu::new(gpu, &data, n * views, &clipmap_gpu)?;
        let render_pass = if gpu.modern {
            vk::RenderPass::null()
        } else {
            pipeline::create_render_pass(gpu)?
        };
        let formats = TargetFormats {
            color: COLOR_FORMAT,
            depth: DEPTH_FORMAT,
            render_pass,
        };
        let method = crate::lod::create(
            method,
            &MethodContext {
                gpu,
                terrain: &terrain,
                data: &data,
                settings: &options.lod,
                formats,
                slots: n * views,
            },
        )?;
        let timestamps =
            gpu.info.queue_families[gpu.queue_family as usize].timestamp_valid_bits > 0;
        let mut slots = Vec::with_capacity(n);
        for i in 0..n {
            slots.push(Self::create_slot(gpu, &options, &formats, i)?);
        }
        let readback_path =
            if slots[0].readback_color.memory_properties().contains(
                vk::MemoryPropertyFlags::DEVICE_LOCAL | vk::MemoryPropertyFlags::HOST_VISIBLE,
            ) {
                ReadbackPath::Unified
            } else {
                ReadbackPath::HostStaging
            };
        Ok(Renderer {
            gpu: gpu.clone(),
            options,
            slots,
            method,
            terrain,
            clipmap,
            clipmap_gpu,
            formats,
            timeline: Timeline::new(gpu)?,
            timestamps,
            next_frame: 0,
            in_flight: VecDeque::new(),
            readback_path,
            stats: RunStats::default(),
        })
    }

    fn create_slot(
        gpu: &Arc<Gpu>,
        o: &RenderOptions,
        formats: &TargetFormats,
        i: usize,
    ) -> Result<Slot> {
        let d = &gpu.device;
        let extent = vk::Extent2D {
            width: o.width,
            height: o.height,
        };
        let color = Image::new(
            gpu,
            &ImageDesc {
                name: &format!("color {i}"),
                format: COLOR_FORMAT,
                extent,
                layers: 1,
                mips: 1,
                usage: vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC,
                aspect: vk::ImageAspectFlags::COLOR,
            },
        )?;
        let depth = Image::new(
            gpu,
            &ImageDesc {
                name: &format!("depth {i}"),
                format: DEPTH_FORMAT,
                extent,
                layers: 1,
                mips: 1,
                usage: vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT
                    | vk::ImageUsageFlags::TRANSFER_SRC,
                aspect: vk::ImageAspectFlags::DEPTH,
            },
        )?;
        let pixels = o.width as u64 * o.height as u64;
        // GpuToCpu picks host-visible memory, preferring cached; on unified-memory devices the
        // only such type is also device-local, so the copy needs no staging there.
        let readback_color = Buffer::new(
            gpu,
            &format!("readback color {i}"),
            pixels * 4,
            vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuToCpu,
        )?;
        let readback_depth = if o.readback_depth {
            Some(Buffer::new(
                gpu,
                &format!("readback depth {i}"),
                pixels * 4,
                vk::BufferUsageFlags::TRANSFER_DST,
                MemoryLocation::GpuToCpu,
            )?)
        } else {
            None
        };
        let pool = unsafe {
            d.create_command_pool(
                &vk::CommandPoolCreateInfo::default()
                    .queue_family_index(gpu.queue_family)
                    .flags(vk::CommandPoolCreateFlags::TRANSIENT),
                None,
            )
        }
        .vk("vkCreateCommandPool")?;
        let mut slot = Slot {
            gpu: gpu.clone(),
            pool,
            cmd: vk::CommandBuffer::null(),
            color,
            depth,
            framebuffer: vk::Framebuffer::null(),
            readback_color,
            readback_depth,
            queries: vk::QueryPool::null(),
            pending: None,
        };
        slot.cmd = unsafe {
            d.allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(pool)
                    .command_buffer_count(1),
            )
        }
        .vk("vkAllocateCommandBuffers")?[0];
        slot.queries = unsafe {
            d.create_query_pool(
                &vk::QueryPoolCreateInfo::default()
                    .query_type(vk::QueryType::TIMESTAMP)
                    .query_count(TIMESTAMPS),
                None,
            )
        }
        .vk("vkCreateQueryPool")?;
        if formats.render_pass != vk::RenderPass::null() {
            let views = [slot.color.view, slot.depth.view];
            slot.framebuffer = unsafe {
                d.create_framebuffer(
                    &vk::FramebufferCreateInfo::default()
                        .render_pass(formats.render_pass)
                        .attachments(&views)
                        .width(o.width)
                        .height(o.height)
                        .layers(1),
                    None,
                )
            }
            .vk("vkCreateFramebuffer")?;
        }
        Ok(slot)
    }

    pub fn gpu(&self) -> &Arc<Gpu> {
        &self.gpu
    }

    pub fn terrain(&self) -> &terrain::TerrainInfo {
        &self.terrain.info
    }

    /// The LOD method (for its counters and, in tests, its tile list).
    pub fn method(&self) -> &dyn LodMethod {
        self.method.as_ref()
    }

    /// The clipmap, when heights come through one (counters, CPU `sample_height`).
    pub fn clipmap(&self) -> Option<&Clipmap> {
        self.clipmap.as_ref()
    }

    /// Tests and tools: GPU heights at level-0 sample positions for the state of the last
    /// rendered frame, `[clipmap_height, single-texture bilinear]` each. Call after
    /// [`Renderer::finish`]; waits for the GPU.
    pub fn probe_heights(&self, points: &[[f32; 2]]) -> Result<Vec<[f32; 2]>> {
        self.probe_in_view(0, points, crate::clipmap::gpu::ProbeKind::Heights)
    }

    /// [`Renderer::probe_heights`] through the state view `view` had in the last frame.
    pub fn probe_heights_in_view(&self, view: usize, points: &[[f32; 2]]) -> Result<Vec<[f32; 2]>> {
        self.probe_in_view(view, points, crate::clipmap::gpu::ProbeKind::Heights)
    }

    /// Tests and tools: what `kind` evaluates at `points` through the state view `view` had in
    /// the last rendered frame. Call after [`Renderer::finish`]; waits for the GPU.
    pub fn probe_in_view(
        &self,
        view: usize,
        points: &[[f32; 2]],
        kind: crate::clipmap::gpu::ProbeKind,
    ) -> Result<Vec<[f32; 2]>> {
        if self.next_frame == 0 || !self.in_flight.is_empty() {
            return Err(Error::invalid(
                "probe_heights",
                "needs a rendered, finished frame",
            ));
        }
        if view >= self.options.views {
            return Err(Error::invalid(
                "probe_heights",
                format!("view {view} of {}", self.options.views),
            ));
        }
        let slot = ((self.next_frame - 1) % self.slots.len() as u64) as usize;
        crate::clipmap::gpu::probe(
            &self.gpu,
            self.terrain.descriptors.layout,
            self.terrain.descriptors.sets[slot * self.options.views + view],
            points,
            kind,
        )
    }

    /// Columns `(first, count)` of view `view` in the frame.
    pub fn view_columns(&self, view: usize) -> (u32, u32) {
        view_columns(self.options.width, self.options.views, view)
    }

    pub fn method_name(&self) -> &'static str {
        self.method.name()
    }

    /// Frames submitted so far.
    pub fn frames_submitted(&self) -> u64 {
        self.next_frame
    }

    /// Renders one frame; delivers to `sink` every frame that is now older than N - 1 frames.
    /// The renderer must draw one view ([`RenderOptions::views`]); see [`Renderer::render_views`].
    pub fn render(
        &mut self,
        request: impl Into<FrameRequest>,
        sink: &mut dyn FrameSink,
    ) -> Result<()> {
        self.render_views(&[request.into()], sink)
    }

    /// Renders one frame of `requests.len() == views` cameras side by side (view `v` in
    /// [`Renderer::view_columns`]`(v)`), every view through the same atlas; the frame's sky
    /// is the first request's. Delivers like [`Renderer::render`]; the delivered frame carries
    /// the first camera.
    pub fn render_views(
        &mut self,
        requests: &[FrameRequest],
        sink: &mut dyn FrameSink,
    ) -> Result<()> {
        let views = self.options.views;
        if requests.len() != views {
            return Err(Error::invalid(
                "views",
                format!("{} cameras for a renderer of {views} views", requests.len()),
            ));
        }
        for request in requests {
            request.camera.validate()?;
            if let Some(sky) = request.sky
                && sky.iter().any(|v| !v.is_finite())
            {
                return Err(Error::invalid("sky colour", "not finite"));
            }
        }
        let request = requests[0];
        let index = self.next_frame;
        let slot_index = (index % self.slots.len() as u64) as usize;
        // The slot's previous frame was delivered after the last submit (N-1 pending at most),
        // so its GPU work is complete and its buffers are free.
        debug_assert!(self.slots[slot_index].pending.is_none());
        let started = Instant::now();
        let mut states: Vec<ViewState> = requests
            .iter()
            .enumerate()
            .map(|(v, r)| ViewState {
                camera: r.camera,
                lod_viewer: r.lod_viewer.unwrap_or(r.camera.position),
                width: self.view_columns(v).1,
                height: self.options.height,
                ground_m: None,
            })
            .collect();
        if let Some(cm) = &mut self.clipmap {
            // One update for all views: the union of their wanted nodes, one atlas.
            let spacing = self.terrain.info.spacing;
            let viewers: Vec<glam::DVec2> = states
                .iter()
                .map(|v| glam::DVec2::new(v.lod_viewer.x / spacing, v.lod_viewer.y / spacing))
                .collect();
            let uploads = cm.update(&viewers);
            // The terrain under each viewer (clamped into the data: the lookup extrapolates
            // outside it), from memory.
            let (w, h) = (
                cm.geometry.width as f64 - 1.0,
                cm.geometry.height as f64 - 1.0,
            );
            for (v, (state, viewer)) in states.iter_mut().zip(&viewers).enumerate() {
                let p = [viewer.x.clamp(0.0, w) as f32, viewer.y.clamp(0.0, h) as f32];
                state.ground_m = Some(cm.sample_height(v, p) as f64);
            }
            self.clipmap_gpu
                .stage_uploads(slot_index, &cm.geometry, &cm.atlas, &uploads)?;
            for (v, quadtree) in cm.views.iter().enumerate() {
                self.clipmap_gpu
                    .write_quadtree(slot_index * views + v, &cm.geometry, quadtree)?;
            }
        }
        for (v, view) in states.iter().enumerate() {
            let view_slot = slot_index * views + v;
            let uniforms = FrameUniforms::new(
                &view.camera,
                view.width as f64 / view.height as f64,
                &self.terrain.info,
                self.options.sun_dir,
            );
            self.terrain.uniforms[view_slot].write(uniforms.as_bytes())?;
            self.method.update(view_slot, view)?;
        }
        let sky = request.sky.unwrap_or(self.options.sky);
        let color_bytes = self.options.width as u64 * self.options.height as u64 * 4;
        let direct = sink
            .direct_target(index, color_bytes)
            .filter(|d| d.host_bytes().len() as u64 >= color_bytes);
        self.record(slot_index, sky, direct.map(|d| d.buffer))?;

        let cmds = [self.slots[slot_index].cmd];
        let signal = [self.timeline.raw];
        let values = [index + 1];
        let mut timeline_info =
            vk::TimelineSemaphoreSubmitInfo::default().signal_semaphore_values(&values);
        let submit = vk::SubmitInfo::default()
            .command_buffers(&cmds)
            .signal_semaphores(&signal)
            .push_next(&mut timeline_info);
        self.gpu.submit(&[submit], vk::Fence::null())?;
        self.slots[slot_index].pending = Some(Pending {
            index,
            camera: request.camera,
            cpu_record_ms: started.elapsed().as_secs_f64() * 1e3,
            triangles: 0,
            direct,
        });
        self.in_flight.push_back(slot_index);
        self.next_frame += 1;
        while self.in_flight.len() >= self.slots.len() {
            self.deliver_oldest(sink)?;
        }
        Ok(())
    }

    /// Delivers every frame still in flight (end of a run).
    pub fn finish(&mut self, sink: &mut dyn FrameSink) -> Result<()> {
        while !self.in_flight.is_empty() {
            self.deliver_oldest(sink)?;
        }
        Ok(())
    }

    fn deliver_oldest(&mut self, sink: &mut dyn FrameSink) -> Result<()> {
        let Some(slot_index) = self.in_flight.pop_front() else {
            return Ok(());
        };
        let index = self.slots[slot_index]
            .pending
            .as_ref()
            .map(|p| p.index)
            .unwrap_or(0);
        let wait_start = Instant::now();
        self.timeline.wait(index + 1, FRAME_TIMEOUT)?;
        let cpu_wait_ms = wait_start.elapsed().as_secs_f64() * 1e3;
        // Is the next frame still running on the GPU while we read this one? (overlap)
        let next_in_flight = !self.in_flight.is_empty() && self.timeline.value()? < index + 2;
        let mut pending = self.slots[slot_index]
            .pending
            .take()
            .expect("in-flight slot has a frame");
        // Known only now for GPU-driven methods.
        let views = self.options.views;
        pending.triangles = (0..views)
            .map(|v| self.method.triangles(slot_index * views + v))
            .sum();
        let (prepass, terrain, readback) = self.read_timestamps(slot_index)?;
        let timings = FrameTimings {
            gpu_prepass_ms: prepass,
            gpu_terrain_ms: terrain,
            gpu_readback_ms: readback,
            cpu_record_ms: pending.cpu_record_ms,
            cpu_wait_ms,
        };
        let slot = &self.slots[slot_index];
        let color_bytes = self.options.width as usize * self.options.height as usize * 4;
        let rgba = match &pending.direct {
            Some(d) => &d.host_bytes()[..color_bytes],
            None => slot
                .readback_color
                .mapped()
                .ok_or_else(|| Error::invalid("readback", "buffer not mapped"))?,
        };
        let depth = match &slot.readback_depth {
            Some(b) => {
                let bytes = b
                    .mapped()
                    .ok_or_else(|| Error::invalid("readback", "depth buffer not mapped"))?;
                // SAFETY: mapped memory is at least 4-byte aligned (Vulkan minMemoryMapAlignment
                // is >= 64) and holds width*height f32 depth values.
                Some(unsafe {
                    std::slice::from_raw_parts(bytes.as_ptr() as *const f32, bytes.len() / 4)
                })
            }
            None => None,
        };
        let view = FrameView {
            index: pending.index,
            width: self.options.width,
            height: self.options.height,
            row_stride: self.options.width as usize * 4,
            rgba,
            depth,
            camera: pending.camera,
            timings,
            triangles: pending.triangles,
        };
        let sink_start = Instant::now();
        let result = sink.frame(&view);
        self.stats.record(
            &timings,
            pending.triangles,
            next_in_flight,
            sink_start.elapsed().as_secs_f64() * 1e3,
        );
        result
    }

    fn read_timestamps(&self, slot_index: usize) -> Result<(f64, f64, f64)> {
        if !self.timestamps {
            return Ok((0.0, 0.0, 0.0));
        }
        let mut ts = [0u64; TIMESTAMPS as usize];
        unsafe {
            self.gpu.device.get_query_pool_results(
                self.slots[slot_index].queries,
                0,
                &mut ts,
                vk::QueryResultFlags::TYPE_64,
            )
        }
        .vk("vkGetQueryPoolResults")?;
        let period = self.gpu.info.limits.timestamp_period as f64 * 1e-6;
        let ms = |a: u64, b: u64| b.saturating_sub(a) as f64 * period;
        Ok((ms(ts[0], ts[1]), ms(ts[1], ts[2]), ms(ts[2], ts[3])))
    }

    /// Records frame work for `slot_index`; the colour is copied into `color_dst` (a sink's
    /// zero-copy target) or else the slot's readback buffer.
    fn record(
        &mut self,
        slot_index: usize,
        sky: [f32; 3],
        color_dst: Option<vk::Buffer>,
    ) -> Result<()> {
        let gpu = self.gpu.clone();
        let d = &gpu.device;
        let b = Barriers::new(&gpu);
        let o = &self.options;
        let slot = &self.slots[slot_index];
        let cmd = slot.cmd;
        let extent = vk::Extent2D {
            width: o.width,
            height: o.height,
        };
        unsafe {
            d.reset_command_pool(slot.pool, vk::CommandPoolResetFlags::empty())
                .vk("vkResetCommandPool")?;
            d.begin_command_buffer(
                cmd,
                &vk::CommandBufferBeginInfo::default()
                    .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
            )
            .vk("vkBeginCommandBuffer")?;
            d.cmd_reset_query_pool(cmd, slot.queries, 0, TIMESTAMPS);
            d.cmd_write_timestamp(cmd, vk::PipelineStageFlags::TOP_OF_PIPE, slot.queries, 0);
        }
        // New atlas nodes first: after every earlier frame's sampling, before this frame's.
        self.clipmap_gpu.record_uploads(cmd, slot_index);
        let views = o.views;
        for v in 0..views {
            let view_slot = slot_index * views + v;
            self.method
                .record_prepass(cmd, view_slot, self.terrain.descriptors.sets[view_slot]);
        }
        let slot = &self.slots[slot_index];
        unsafe {
            d.cmd_write_timestamp(cmd, vk::PipelineStageFlags::COMPUTE_SHADER, slot.queries, 1)
        };

        // The previous use of these images (N frames ago) ended with a copy; their contents are
        // discarded (UNDEFINED) but the transition must still wait for that copy.
        b.image(
            cmd,
            slot.color.raw,
            color_range(),
            ImageAccess::TransferSrcDiscard,
            ImageAccess::ColorAttachment,
        );
        b.image(
            cmd,
            slot.depth.raw,
            depth_range(),
            ImageAccess::TransferSrcDiscard,
            ImageAccess::DepthAttachment,
        );
        let clear = [
            vk::ClearValue {
                color: vk::ClearColorValue {
                    float32: [sky[0], sky[1], sky[2], 1.0],
                },
            },
            // Reversed-Z: 0 is the far plane.
            vk::ClearValue {
                depth_stencil: vk::ClearDepthStencilValue {
                    depth: 0.0,
                    stencil: 0,
                },
            },
        ];
        let area = vk::Rect2D {
            offset: vk::Offset2D::default(),
            extent,
        };
        unsafe {
            if gpu.modern {
                let color_att = [vk::RenderingAttachmentInfo::default()
                    .image_view(slot.color.view)
                    .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                    .load_op(vk::AttachmentLoadOp::CLEAR)
                    .store_op(vk::AttachmentStoreOp::STORE)
                    .clear_value(clear[0])];
                let depth_att = vk::RenderingAttachmentInfo::default()
                    .image_view(slot.depth.view)
                    .image_layout(vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL)
                    .load_op(vk::AttachmentLoadOp::CLEAR)
                    .store_op(vk::AttachmentStoreOp::STORE)
                    .clear_value(clear[1]);
                d.cmd_begin_rendering(
                    cmd,
                    &vk::RenderingInfo::default()
                        .render_area(area)
                        .layer_count(1)
                        .color_attachments(&color_att)
                        .depth_attachment(&depth_att),
                );
            } else {
                d.cmd_begin_render_pass(
                    cmd,
                    &vk::RenderPassBeginInfo::default()
                        .render_pass(self.formats.render_pass)
                        .framebuffer(slot.framebuffer)
                        .render_area(area)
                        .clear_values(&clear),
                    vk::SubpassContents::INLINE,
                );
            }
        }
        for v in 0..views {
            let (x, width) = view_columns(o.width, views, v);
            unsafe {
                d.cmd_set_viewport(
                    cmd,
                    0,
                    &[vk::Viewport {
                        x: x as f32,
                        y: 0.0,
                        width: width as f32,
                        height: o.height as f32,
                        min_depth: 0.0,
                        max_depth: 1.0,
                    }],
                );
                d.cmd_set_scissor(
                    cmd,
                    0,
                    &[vk::Rect2D {
                        offset: vk::Offset2D { x: x as i32, y: 0 },
                        extent: vk::Extent2D {
                            width,
                            height: o.height,
                        },
                    }],
                );
            }
            let view_slot = slot_index * views + v;
            let frame_set = self.terrain.descriptors.sets[view_slot];
            self.method.record_draw(cmd, view_slot, frame_set);
        }
        let slot = &self.slots[slot_index];
        unsafe {
            if gpu.modern {
                d.cmd_end_rendering(cmd);
            } else {
                d.cmd_end_render_pass(cmd);
            }
            d.cmd_write_timestamp(cmd, vk::PipelineStageFlags::BOTTOM_OF_PIPE, slot.queries, 2);
        }
        b.image(
            cmd,
            slot.color.raw,
            color_range(),
            ImageAccess::ColorAttachment,
            ImageAccess::TransferSrc,
        );
        let copy = |aspect| {
            vk::BufferImageCopy::default()
                .image_subresource(vk::ImageSubresourceLayers {
                    aspect_mask: aspect,
                    mip_level: 0,
                    base_array_layer: 0,
                    layer_count: 1,
                })
                .image_extent(vk::Extent3D {
                    width: o.width,
                    height: o.height,
                    depth: 1,
                })
        };
        unsafe {
            d.cmd_copy_image_to_buffer(
                cmd,
                slot.color.raw,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                color_dst.unwrap_or(slot.readback_color.raw),
                &[copy(vk::ImageAspectFlags::COLOR)],
            );
        }
        if let Some(depth_buffer) = &slot.readback_depth {
            b.image(
                cmd,
                slot.depth.raw,
                depth_range(),
                ImageAccess::DepthAttachment,
                ImageAccess::TransferSrc,
            );
            unsafe {
                d.cmd_copy_image_to_buffer(
                    cmd,
                    slot.depth.raw,
                    vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                    depth_buffer.raw,
                    &[copy(vk::ImageAspectFlags::DEPTH)],
                );
            }
        } else {
            // Keep the depth image's state uniform across frames (TransferSrc before reuse).
            b.image(
                cmd,
                slot.depth.raw,
                depth_range(),
                ImageAccess::DepthAttachment,
                ImageAccess::TransferSrc,
            );
        }
        b.memory(cmd, MemoryAccess::TransferWrite, MemoryAccess::HostRead);
        unsafe {
            d.cmd_write_timestamp(cmd, vk::PipelineStageFlags::BOTTOM_OF_PIPE, slot.queries, 3);
            d.end_command_buffer(cmd).vk("vkEndCommandBuffer")?;
        }
        Ok(())
    }
}

/// Columns `(first, count)` of view `view` of `views` side by side in `width` columns.
pub fn view_columns(width: u32, views: usize, view: usize) -> (u32, u32) {
    let edge = |v: usize| (width as u64 * v as u64 / views as u64) as u32;
    (edge(view), edge(view + 1) - edge(view))
}

impl Drop for Renderer {
    fn drop(&mut self) {
        // Outstanding frames must finish before their command buffers and images go away.
        let _ = self.timeline.wait(self.next_frame, FRAME_TIMEOUT);
        let _ = self.gpu.wait_idle();
        self.slots.clear();
        if self.formats.render_pass != vk::RenderPass::null() {
            // The method's pipelines reference the render pass only at creation; destroying it
            // here (before the method drops) is allowed by the spec.
            unsafe {
                self.gpu
                    .device
                    .destroy_render_pass(self.formats.render_pass, None)
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::view_columns;

    #[test]
    fn views_tile_the_frame_without_gaps_or_overlap() {
        for width in [1u32, 7, 96, 97, 1921] {
            for views in 1..=super::MAX_VIEWS.min(width as usize) {
                let mut next = 0;
                for v in 0..views {
                    let (x, w) = view_columns(width, views, v);
                    assert_eq!(x, next, "{width} / {views}: view {v}");
                    assert!(w >= width / views as u32, "{width} / {views}: view {v}");
                    next = x + w;
                }
                assert_eq!(next, width, "{width} / {views}");
            }
        }
    }
}
