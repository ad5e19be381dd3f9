//! The render loop: N frames in flight, each frame slot with its own command buffer, targets,
//! readback buffers and timestamp queries, ordered by one timeline semaphore.
//!
//! Frame `k` uses frame slot `k % N` and signals timeline value `k + 1`. After submitting frame
//! `k` the host delivers frame `k - (N - 1)` (waiting for its value only), so with N >= 2 the
//! host reads frame `k - 1` while the GPU works on frame `k`: it never waits on newer work.
//!
//! A frame draws 1..=[`MAX_VIEWS`] cameras side by side. Per-view state (uniforms, set 0, the
//! method's buffers, the clipmap's quadtree) lives in view slots ([`crate::slots`]).
//!
//! Files: [`targets`] (the terrain pass and its images), [`delivery`] (readback and
//! timestamps), `slot` (what a frame slot owns), `record` (one frame's commands), [`stats`],
//! [`analysis`] (an optional stage after the terrain pass: the evaluator's GPU metrics).

pub mod analysis;
pub mod delivery;
#[cfg(feature = "test-support")]
mod probe;
#[cfg(feature = "test-support")]
pub use probe::TerrainProbePoint;
mod record;
pub mod settings;
mod slot;
pub mod stats;
pub mod targets;

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::{Duration, Instant};

use ash::vk;

use crate::clipmap::Clipmap;
use crate::clipmap::stage::ClipmapStage;
use crate::dataset::{Level0, Terrain};
use crate::driver::Gpu;
use crate::driver::sync::Timeline;
use crate::error::{Error, Result};
use crate::frame::{FrameUniforms, Lighting, TerrainGpu, TerrainInfo, ViewState};
use crate::lod::{LodMethod, MethodConfig, MethodContext};
use crate::readback::{DirectTarget, FrameSink, FrameTimings, FrameView};
use crate::scene::Camera;
use crate::slots::{FrameSlot, SlotLayout};
pub use delivery::ReadbackPath;
pub use settings::EarthGeometry;
use slot::{FrameResources, Pending};
use stats::RunStats;
use targets::TerrainPass;

/// How long the host waits for one frame before calling the GPU hung.
const FRAME_TIMEOUT: Duration = Duration::from_secs(60);

/// Most views (cameras) drawn into one frame.
pub const MAX_VIEWS: usize = 4;

/// Most frames in flight.
pub const MAX_FRAMES_IN_FLIGHT: usize = 8;

/// Checks a frames-in-flight count (1..=[`MAX_FRAMES_IN_FLIGHT`]).
pub fn check_frames_in_flight(n: usize) -> Result<()> {
    if (1..=MAX_FRAMES_IN_FLIGHT).contains(&n) {
        Ok(())
    } else {
        Err(Error::invalid(
            "frames_in_flight",
            format!("{n} is outside 1..={MAX_FRAMES_IN_FLIGHT}"),
        ))
    }
}

/// Checks a views-per-frame count against the frame's width (one column per view at least).
pub fn check_views(views: usize, width: u32) -> Result<()> {
    if (1..=MAX_VIEWS).contains(&views) && views as u64 <= width as u64 {
        Ok(())
    } else {
        Err(Error::invalid(
            "views",
            format!(
                "{views} views in {width} columns: need 1..={MAX_VIEWS} views and at most one per column"
            ),
        ))
    }
}

/// Render-target and loop settings.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    pub width: u32,
    pub height: u32,
    pub frames_in_flight: usize,
    pub readback_depth: bool,
    /// The sun and the sky (the clear colour; a frame may override it, the haze keeps it).
    pub light: Lighting,
    /// Cameras per frame (1..=[`MAX_VIEWS`]), side by side: view `v` covers columns
    /// [`view_columns`]`(width, views, v)`.
    pub views: usize,
    /// Ellipsoid or flat geometry for data on the earth (`Config::open_renderer` builds the
    /// lattice from it).
    pub earth: EarthGeometry,
}

impl RenderOptions {
    fn layout(&self) -> SlotLayout {
        SlotLayout {
            frames_in_flight: self.frames_in_flight,
            views: self.views,
        }
    }

    fn extent(&self) -> vk::Extent2D {
        vk::Extent2D {
            width: self.width,
            height: self.height,
        }
    }

    /// Checks the options against each other and the device's limits.
    fn check(&self, gpu: &Gpu) -> Result<()> {
        let limits = &gpu.info.limits;
        if self.width == 0
            || self.height == 0
            || self.width > limits.max_framebuffer_width
            || self.height > limits.max_framebuffer_height
        {
            return Err(Error::invalid(
                "resolution",
                format!(
                    "{}x{} is outside 1..={}x{} (device limit)",
                    self.width,
                    self.height,
                    limits.max_framebuffer_width,
                    limits.max_framebuffer_height
                ),
            ));
        }
        check_frames_in_flight(self.frames_in_flight)?;
        check_views(self.views, self.width)
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
        Self::with_extra_views_on(main, extra, None)
    }

    /// [`FrameRequest::with_extra_views`] with the offsets in the local frame at the main
    /// camera when `world` is given (the terrain on the ellipsoid: [`Renderer::earth_frame`];
    /// `ViewOffset::apply_on`).
    pub fn with_extra_views_on(
        main: Camera,
        extra: &[crate::scene::ViewOffset],
        world: Option<&crate::geo::EnuFrame>,
    ) -> Vec<Self> {
        std::iter::once(main)
            .chain(extra.iter().map(|o| o.apply_on(&main, world)))
            .map(FrameRequest::from)
            .collect()
    }

    fn check(&self) -> Result<()> {
        self.camera.validate()?;
        if let Some(sky) = self.sky
            && sky.iter().any(|v| !v.is_finite())
        {
            return Err(Error::invalid("sky colour", "not finite"));
        }
        Ok(())
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

pub struct Renderer {
    gpu: Arc<Gpu>,
    pub options: RenderOptions,
    layout: SlotLayout,
    // Field order is drop order: frame slots and the method hold objects that reference
    // `terrain`'s layouts and the clipmap's buffers; the legacy render pass goes last.
    slots: Vec<FrameResources>,
    method: Box<dyn LodMethod>,
    terrain: TerrainGpu,
    clipmap: ClipmapStage,
    pass: TerrainPass,
    timeline: Timeline,
    next_frame: u64,
    in_flight: VecDeque<FrameSlot>,
    pub readback_path: ReadbackPath,
    pub stats: RunStats,
    /// Recorded after the terrain pass of every frame when set (dropped after the GPU idles:
    /// `Drop` waits first).
    analysis: Option<Box<dyn analysis::FrameAnalysis>>,
    /// The world frame on the earth and the datum code of its heights
    /// (`output::ring::layout::DATUM_*`): frames then carry the camera's WGS84 pose.
    pub world: Option<(crate::geo::EnuFrame, u32)>,
    /// The geolocation lattice the terrain is drawn through (None: the flat world), and the
    /// grid's nominal spacing: LOD viewers are carried into the grid's frame through it.
    lattice: Option<(Arc<crate::geo::Lattice>, f64)>,
}

impl Renderer {
    /// `data`: an `Arc<Heightmap>` (or a `Terrain`) is shared; a `&Heightmap` is copied.
    pub fn new(
        gpu: &Arc<Gpu>,
        data: impl Into<Terrain>,
        method: impl Into<MethodConfig>,
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
        method: impl Into<MethodConfig>,
        options: RenderOptions,
        clipmap: Option<Clipmap>,
    ) -> Result<Self> {
        Self::with_world(gpu, data, method, options, clipmap, None)
    }

    /// [`Renderer::with_clipmap`] with the terrain's samples placed on the earth by
    /// `lattice` (docs/coordinates.md, "Geodetic geometry"); None: the flat world.
    pub fn with_world(
        gpu: &Arc<Gpu>,
        data: impl Into<Terrain>,
        method: impl Into<MethodConfig>,
        options: RenderOptions,
        clipmap: Option<Clipmap>,
        lattice: Option<&crate::geo::Lattice>,
    ) -> Result<Self> {
        let data: Terrain = data.into();
        let method = method.into();
        options.check(gpu)?;
        if let Some(c) = &clipmap {
            check_level0(c, &data)?;
            check_normal_axes(c, lattice)?;
        }
        let layout = options.layout();
        let clipmap = ClipmapStage::new(gpu, clipmap, layout)?;
        let terrain = TerrainGpu::new(gpu, &data, layout.view_slots(), &clipmap.device, lattice)?;
        let lattice = lattice.map(|l| Arc::new(l.clone()));
        let pass = TerrainPass::new(gpu)?;
        let method = crate::lod::create(
            &method,
            &MethodContext {
                gpu,
                terrain: &terrain,
                data: &data,
                formats: pass.formats,
                slots: layout.view_slots(),
                lattice: lattice.as_ref(),
            },
        )?;
        let slots = layout
            .frame_slots()
            .map(|f| FrameResources::new(gpu, &pass, options.extent(), options.readback_depth, f))
            .collect::<Result<Vec<_>>>()?;
        let readback_path = slots[0].readback.path();
        let lattice = lattice.map(|l| (l, data.spacing()));
        Ok(Renderer {
            gpu: gpu.clone(),
            options,
            layout,
            slots,
            method,
            terrain,
            clipmap,
            pass,
            timeline: Timeline::new(gpu)?,
            next_frame: 0,
            in_flight: VecDeque::new(),
            readback_path,
            stats: RunStats::default(),
            analysis: None,
            world: None,
            lattice,
        })
    }

    /// Records `stage` after the terrain pass of every later frame and lets it collect its
    /// results when each frame is delivered. Only between frames (none in flight).
    pub fn set_analysis(&mut self, stage: Box<dyn analysis::FrameAnalysis>) -> Result<()> {
        if !self.in_flight.is_empty() {
            return Err(Error::invalid(
                "frame analysis",
                "set while frames are in flight",
            ));
        }
        self.analysis = Some(stage);
        Ok(())
    }

    pub fn gpu(&self) -> &Arc<Gpu> {
        &self.gpu
    }

    pub fn terrain(&self) -> &TerrainInfo {
        &self.terrain.info
    }

    /// The build of the terrain shaders this renderer draws with (its world and source of
    /// heights): what a probe of a terrain shader must run.
    pub fn terrain_variant(&self) -> crate::driver::shaders::TerrainVariant {
        self.terrain.variant
    }

    /// The LOD method (for its counters and, in tests, its tile list).
    pub fn method(&self) -> &dyn LodMethod {
        self.method.as_ref()
    }

    /// The clipmap, when heights come through one (counters, CPU `sample_height`).
    pub fn clipmap(&self) -> Option<&Clipmap> {
        self.clipmap.host()
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
        if requests.len() != self.layout.views {
            return Err(Error::invalid(
                "views",
                format!(
                    "{} cameras for a renderer of {} views",
                    requests.len(),
                    self.layout.views
                ),
            ));
        }
        for request in requests {
            request.check()?;
        }
        let index = self.next_frame;
        let frame = self.layout.frame_slot(index);
        // The slot's previous frame was delivered after the last submit (N-1 pending at most),
        // so its GPU work is complete and its buffers are free.
        debug_assert!(self.slots[frame.index()].pending.is_none());
        let started = Instant::now();
        self.update_views(frame, requests)?;
        let direct = self.direct_target(index, sink);
        self.record(frame, index, requests, direct.map(|d| d.buffer))?;
        self.submit(frame, index)?;
        self.slots[frame.index()].pending = Some(Pending {
            index,
            camera: requests[0].camera,
            cpu_record_ms: started.elapsed().as_secs_f64() * 1e3,
            direct,
        });
        self.in_flight.push_back(frame);
        self.next_frame += 1;
        while self.in_flight.len() >= self.slots.len() {
            self.deliver_oldest(sink, false)?;
        }
        Ok(())
    }

    /// Host side of every view of frame slot `frame`: the clipmap's stage, the frame uniforms
    /// and the method's per-view update.
    fn update_views(&mut self, frame: FrameSlot, requests: &[FrameRequest]) -> Result<()> {
        let viewers: Vec<glam::DVec3> = requests
            .iter()
            .map(|r| self.grid_viewer(r.lod_viewer.unwrap_or(r.camera.position)))
            .collect();
        let ground = self.clipmap.prepare(frame, &viewers)?;
        for (v, view) in self.layout.view_slots_of(frame).enumerate() {
            let state = ViewState {
                camera: requests[v].camera,
                lod_viewer: viewers[v],
                width: self.view_columns(v).1,
                height: self.options.height,
                ground_m: ground[v],
            };
            let uniforms = FrameUniforms::new(
                &state.camera,
                state.width as f64 / state.height as f64,
                &self.terrain.info,
                &self.options.light,
            );
            self.terrain.write_uniforms(view, &uniforms)?;
            self.method.update(view, &state)?;
        }
        Ok(())
    }

    /// The world frame on the earth when the terrain is drawn on the ellipsoid (None: flat):
    /// where rig offsets (`[[render.extra_views]]`) are applied in the local frame.
    pub fn earth_frame(&self) -> Option<&crate::geo::EnuFrame> {
        self.lattice.as_ref().map(|(l, _)| &l.frame)
    }

    /// Where LOD distances are measured from, in the grid's frame (`x = col * spacing`,
    /// `y = row * spacing`, `z` = height): on the flat world the world point itself; on the
    /// earth the sample position under it and its height above the lattice surface (the
    /// terrain's datum: the lattice lies on its zero surface)
    /// ([`crate::geo::Lattice::sample_at`]), so every method's and the clipmap's distances and
    /// reference heights refer to the samples actually below the viewer (docs/coordinates.md).
    fn grid_viewer(&self, world: glam::DVec3) -> glam::DVec3 {
        match &self.lattice {
            None => world,
            Some((l, spacing)) => {
                let (s, height) = l.sample_at(world);
                glam::DVec3::new(s.x * spacing, s.y * spacing, height)
            }
        }
    }

    /// The sink's zero-copy target for frame `index` ([`FrameSink::direct_target`]), if it
    /// offers one large enough for the frame's colour.
    fn direct_target(&self, index: u64, sink: &mut dyn FrameSink) -> Option<DirectTarget> {
        let color_bytes = self.color_bytes() as u64;
        sink.direct_target(index, color_bytes)
            .filter(|d| d.host_bytes().len() as u64 >= color_bytes)
    }

    /// Bytes of one frame's RGBA8 colour.
    fn color_bytes(&self) -> usize {
        self.options.width as usize * self.options.height as usize * 4
    }

    /// Submits frame slot `frame`'s commands as frame `index` (signals timeline `index + 1`).
    fn submit(&self, frame: FrameSlot, index: u64) -> Result<()> {
        let cmds = [self.slots[frame.index()].cmd];
        let signal = [self.timeline.raw];
        let values = [index + 1];
        let mut timeline_info =
            vk::TimelineSemaphoreSubmitInfo::default().signal_semaphore_values(&values);
        let submit = vk::SubmitInfo::default()
            .command_buffers(&cmds)
            .signal_semaphores(&signal)
            .push_next(&mut timeline_info);
        self.gpu.submit(&[submit], vk::Fence::null())
    }

    /// Delivers every frame still in flight (end of a run).
    pub fn finish(&mut self, sink: &mut dyn FrameSink) -> Result<()> {
        while !self.in_flight.is_empty() {
            self.deliver_oldest(sink, true)?;
        }
        Ok(())
    }

    /// Delivers the oldest frame in flight; `drained`: by [`Renderer::finish`].
    fn deliver_oldest(&mut self, sink: &mut dyn FrameSink, drained: bool) -> Result<()> {
        let Some(frame) = self.in_flight.pop_front() else {
            return Ok(());
        };
        let pending = self.slots[frame.index()]
            .pending
            .take()
            .expect("an in-flight slot holds a frame");
        let wait_start = Instant::now();
        self.timeline.wait(pending.index + 1, FRAME_TIMEOUT)?;
        let cpu_wait_ms = wait_start.elapsed().as_secs_f64() * 1e3;
        // Is the next frame still running on the GPU while we read this one? (overlap)
        let overlapped = !self.in_flight.is_empty() && self.timeline.value()? < pending.index + 2;
        // Known only now for GPU-driven methods.
        let triangles = self
            .layout
            .view_slots_of(frame)
            .map(|view| self.method.triangles(view))
            .sum();
        let budget_overflow = self
            .layout
            .view_slots_of(frame)
            .map(|view| self.method.budget_overflow(view))
            .sum();
        let tiles = self
            .layout
            .view_slots_of(frame)
            .map(|view| self.method.tiles(view))
            .sum();
        if let Some(stage) = &mut self.analysis {
            stage.complete(frame, pending.index)?;
        }
        let slot = &self.slots[frame.index()];
        let passes = slot.timestamps.read()?;
        let timings = FrameTimings {
            gpu_prepass_ms: passes.prepass_ms,
            gpu_terrain_ms: passes.terrain_ms,
            gpu_readback_ms: passes.readback_ms,
            cpu_record_ms: pending.cpu_record_ms,
            cpu_wait_ms,
        };
        let (readback_rgba, depth) = slot.readback.frame()?;
        let rgba = match &pending.direct {
            Some(d) => &d.host_bytes()[..self.color_bytes()],
            None => readback_rgba,
        };
        let view = FrameView {
            index: pending.index,
            width: self.options.width,
            height: self.options.height,
            row_stride: self.options.width as usize * 4,
            rgba,
            depth,
            camera: pending.camera,
            geo: self
                .world
                .map(|(frame, height_datum)| crate::readback::GeoFix {
                    pose: crate::geo::GeoPose::from_world(&frame, &(&pending.camera).into()),
                    height_datum,
                }),
            timings,
            triangles,
            budget_overflow,
            tiles,
        };
        let sink_start = Instant::now();
        let result = sink.frame(&view);
        let sink_ms = sink_start.elapsed().as_secs_f64() * 1e3;
        self.stats
            .record(&timings, triangles, overlapped, sink_ms, drained);
        result
    }
}

/// A clipmap's level 0 must be the data set's.
fn check_level0(clipmap: &Clipmap, data: &Terrain) -> Result<()> {
    let g = &clipmap.geometry;
    if (g.width, g.height) == (data.width() as u64, data.height() as u64) {
        return Ok(());
    }
    Err(Error::invalid(
        "clipmap",
        format!(
            "level 0 is {}x{} but the height map is {}x{} (use the data set's level 0)",
            g.width,
            g.height,
            data.width(),
            data.height()
        ),
    ))
}

/// The clipmap's shading planes hold normals in the axes the renderer lights in: world axes
/// through the renderer's lattice on the earth, the grid's in the flat world
/// (`Geometry::with_world`).
fn check_normal_axes(clipmap: &Clipmap, lattice: Option<&crate::geo::Lattice>) -> Result<()> {
    match (clipmap.geometry.world.as_deref(), lattice) {
        (None, None) => Ok(()),
        (Some(a), Some(b)) if a == b => Ok(()),
        _ => Err(Error::invalid(
            "clipmap",
            "its normals are not in the renderer's axes (build its geometry `with_world` the \
             renderer's lattice)",
        )),
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
