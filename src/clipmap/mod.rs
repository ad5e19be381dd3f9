//! The chunked clipmap (background.md §2): a node atlas shared by all views, one clipped
//! quadtree per view, asynchronous streaming with the four-step update every frame, and a CPU
//! `sample_height` that returns what the GPU samples.
//!
//! `Clipmap` is the host side; [`gpu::ClipmapGpu`] mirrors it on the device (atlas texture
//! array, per-slot quadtree buffers, per-slot staging). See `docs/clipmap.md`.

pub mod atlas;
pub mod gpu;
#[cfg(feature = "test-support")]
pub mod probe;
pub mod quadtree;
pub mod stage;
pub mod streaming;

use std::collections::{HashMap, HashSet, VecDeque};
use std::path::Path;
use std::sync::Arc;

use glam::DVec2;

use crate::dataset::NodeStore;
use crate::dataset::interp::{self, NormalAxes};
use crate::dataset::tiles::Dataset;
use crate::error::{Error, Result};
use crate::geo::Lattice;
use crate::gpu_constants::CLIPMAP_MAX_LEVELS;
use atlas::Atlas;
use quadtree::ViewQuadtree;
use streaming::{LoadResult, Streamer};

/// A node of the pyramid: level and position in that level's node grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct NodeKey {
    pub lod: u32,
    pub x: u32,
    pub y: u32,
}

impl NodeKey {
    pub fn parent(self) -> NodeKey {
        NodeKey {
            lod: self.lod + 1,
            x: self.x / 2,
            y: self.y / 2,
        }
    }
}

/// One node as loaded: `side x side` texels, borders included, row 0 = south.
#[derive(Clone, Debug, Default)]
pub struct NodeData {
    pub heights: Vec<f32>,
    /// RGBA8 sRGB albedo when the data set has an albedo layer.
    pub rgba: Option<Vec<u8>>,
}

/// Where nodes come from (the data set on disk; tests wrap it to fail or withhold nodes).
/// Called on worker threads.
pub trait NodeSource: Send + Sync {
    fn load(&self, key: NodeKey) -> Result<NodeData>;
    /// Tile fetch counters, for sources that fetch tiles (XYZ).
    fn tile_counts(&self) -> Option<crate::dataset::xyz::XyzCounts> {
        None
    }
}

/// Any node store of the dataset layer (a data set directory, live XYZ tiles) as a source.
pub struct StoreSource(pub Arc<dyn NodeStore>);

impl NodeSource for StoreSource {
    fn load(&self, key: NodeKey) -> Result<NodeData> {
        let node = self.0.read_node(key.lod, key.x, key.y)?;
        Ok(NodeData {
            heights: node.heights,
            rgba: (!node.rgba.is_empty()).then_some(node.rgba),
        })
    }
    fn tile_counts(&self) -> Option<crate::dataset::xyz::XyzCounts> {
        self.0.tile_counts()
    }
}

/// A `vkterrain preprocess` data set as a node source.
pub struct DatasetSource {
    pub dataset: Dataset,
}

impl DatasetSource {
    pub fn open(dir: &Path) -> Result<Self> {
        Ok(DatasetSource {
            dataset: Dataset::open(dir)?,
        })
    }
}

impl NodeSource for DatasetSource {
    fn load(&self, key: NodeKey) -> Result<NodeData> {
        // Sizes and finiteness are checked for every source by `Geometry::check`.
        let node = self.dataset.read_node(key.lod, key.x, key.y)?;
        Ok(NodeData {
            heights: node.heights,
            rgba: (!node.rgba.is_empty()).then_some(node.rgba),
        })
    }
}

/// Node geometry of a pyramid: centre and border texels, node counts per level.
#[derive(Clone, Debug, PartialEq)]
pub struct Geometry {
    /// Level-0 samples per side.
    pub width: u64,
    pub height: u64,
    pub center: u32,
    pub border: u32,
    pub levels: Vec<(u32, u32)>,
    /// Metres between level-0 samples: the LOD metric (north-south on a square grid; the
    /// smallest metric spacing on a native non-square grid, [`Geometry::with_native_spacing`]).
    pub spacing: f64,
    /// Stated metres between level-0 samples along x and y (the normals' slopes).
    pub axis_spacing: [f64; 2],
    /// Level-0 height range (metres), for the colour ramp of untextured data.
    pub height_range: [f32; 2],
    /// On the earth, the geolocation lattice the terrain is drawn through: the shading
    /// planes' normals are then in world axes ([`Geometry::with_world`]); None: the grid's.
    pub world: Option<Arc<Lattice>>,
}

impl Geometry {
    /// The geometry of any node store.
    pub fn of_store(store: &dyn NodeStore) -> Self {
        let l = store.layout();
        Geometry {
            width: l.width,
            height: l.height,
            center: l.center,
            border: l.border,
            levels: (0..l.levels()).map(|lod| l.nodes(lod)).collect(),
            spacing: store.spacing()[1],
            axis_spacing: store.spacing(),
            height_range: store.height_range(),
            world: None,
        }
    }

    /// The geometry for a native non-square grid drawn on the ellipsoid: the LOD metric as
    /// the level-0 reader takes it (`tiles::native_lod_spacing`); square grids are unchanged.
    pub fn with_native_spacing(mut self, georef: Option<&crate::dataset::crs::Georef>) -> Self {
        if !crate::dataset::tiles::is_square(self.axis_spacing) {
            self.spacing =
                crate::dataset::tiles::native_lod_spacing(georef, self.height, self.axis_spacing);
        }
        self
    }

    /// The geometry for a terrain drawn through `lattice` on the earth: normals in world
    /// axes, where the drawing shaders light them (docs/coordinates.md, "Normals on the
    /// earth").
    pub fn with_world(mut self, lattice: Option<Arc<Lattice>>) -> Self {
        self.world = lattice;
        self
    }

    pub fn of(ds: &Dataset) -> Self {
        let l = &ds.layout;
        Geometry {
            width: l.width,
            height: l.height,
            center: l.center,
            border: l.border,
            levels: (0..l.levels()).map(|lod| l.nodes(lod)).collect(),
            spacing: ds.manifest.spacing[1],
            axis_spacing: ds.manifest.spacing,
            height_range: ds.manifest.height_range,
            world: None,
        }
    }

    /// Mip levels of the normal and albedo layers (at most 4: the 2-texel border keeps node
    /// edges meaningful for a few halvings; the coarser levels are the clipmap's own rings).
    pub fn shading_mips(&self) -> u32 {
        (u32::BITS - self.side().leading_zeros()).min(4)
    }

    /// Side of mip `m` of a layer (Vulkan's `max(1, side >> m)`).
    pub fn mip_side(&self, m: u32) -> u32 {
        (self.side() >> m).max(1)
    }

    /// Texels of one shading plane over all its mips.
    pub fn shading_texels(&self) -> u64 {
        (0..self.shading_mips())
            .map(|m| (self.mip_side(m) as u64).pow(2))
            .sum()
    }

    /// The shading planes of node `key` for the atlas: RGBA8 snorm normals (central
    /// differences inside the node, borders included; one-sided at its outer texels; in world
    /// axes on the earth) with their mips, followed by RGBA8 sRGB albedo (the data set's, else
    /// the height/slope ramp) with its mips (2x2 box averages per channel; normals are
    /// renormalised in the shader).
    pub fn shading(&self, key: NodeKey, node: &NodeData) -> Vec<u8> {
        let s = self.side() as usize;
        let texels = s * s;
        let scale = (1u64 << key.lod.min(62)) as f64;
        let step = self.axis_spacing.map(|a| a * scale);
        let heights = |i: usize, j: usize| node.heights[j * s + i] as f64;
        let grid_normals = || interp::normals_snorm8(s, s, &NormalAxes::Grid(step), heights);
        let normals = match &self.world {
            None => grid_normals(),
            Some(lattice) => {
                // Texel (i, j) of node (x, y) is level-`lod` sample `x * center + i - border`
                // (unclamped: beyond the data the lattice extrapolates, so the chords stay
                // non-zero), whose centre is level-0 sample `t * 2^lod + (2^lod - 1) / 2`
                // (`clipmap_level_coord` in clipmap.wgsl).
                let c = self.center as f64;
                let b = self.border as f64;
                let origin = DVec2::new(key.x as f64 * c - b, key.y as f64 * c - b) * scale
                    + DVec2::splat((scale - 1.0) / 2.0);
                let position = |i: usize, j: usize, height: f64| {
                    lattice.position(origin + DVec2::new(i as f64, j as f64) * scale, height)
                };
                interp::normals_snorm8(s, s, &NormalAxes::World(&position), heights)
            }
        };
        let albedo = match &node.rgba {
            Some(rgba) => rgba.clone(),
            None => {
                // The ramp goes by the slope: the grid frame's normals.
                let grid;
                let slopes: &[u8] = if self.world.is_some() {
                    grid = grid_normals();
                    &grid
                } else {
                    &normals
                };
                let [lo, hi] = self.height_range;
                let span = (hi - lo).max(1.0);
                (0..texels)
                    .flat_map(|t| {
                        crate::dataset::ramp_rgba(node.heights[t], lo, span, slopes[t * 4 + 2])
                    })
                    .collect()
            }
        };
        let mut out = Vec::with_capacity(self.shading_texels() as usize * 8);
        for (plane, signed) in [(normals, true), (albedo, false)] {
            let mut level = plane;
            for m in 0..self.shading_mips() {
                out.extend_from_slice(&level);
                if m + 1 < self.shading_mips() {
                    level = halve(&level, self.mip_side(m), self.mip_side(m + 1), signed);
                }
            }
        }
        out
    }

    pub fn side(&self) -> u32 {
        self.center + 2 * self.border
    }

    /// Rejects a node of the wrong size or with non-finite heights (whatever the source).
    pub fn check(&self, key: NodeKey, node: &NodeData) -> Result<()> {
        let want = (self.side() as usize).pow(2);
        let what = || format!("node {}/{}/{}", key.lod, key.x, key.y);
        if node.heights.len() != want || node.rgba.as_ref().is_some_and(|a| a.len() != want * 4) {
            return Err(Error::invalid(
                what(),
                format!("{} heights, expected {want}", node.heights.len()),
            ));
        }
        if let Some(bad) = node.heights.iter().position(|h| !h.is_finite()) {
            return Err(Error::invalid(
                what(),
                format!("height {bad} is not finite: corrupt node"),
            ));
        }
        Ok(())
    }
}

/// 2x2 box average of an RGBA8 image (`from` -> `to` texels per side, `to = max(1, from / 2)`),
/// bytes read as i8 when `signed`.
fn halve(src: &[u8], from: u32, to: u32, signed: bool) -> Vec<u8> {
    let (from, to) = (from as usize, to as usize);
    let get = |x: usize, y: usize, c: usize| {
        let b = src[(y.min(from - 1) * from + x.min(from - 1)) * 4 + c];
        if signed { (b as i8) as i32 } else { b as i32 }
    };
    let mut out = Vec::with_capacity(to * to * 4);
    for y in 0..to {
        for x in 0..to {
            for c in 0..4 {
                let sum = get(2 * x, 2 * y, c)
                    + get(2 * x + 1, 2 * y, c)
                    + get(2 * x, 2 * y + 1, c)
                    + get(2 * x + 1, 2 * y + 1, c);
                let v = (sum as f32 / 4.0).round() as i32;
                out.push(if signed { (v as i8) as u8 } else { v as u8 });
            }
        }
    }
    out
}

/// `[clipmap]` in the config.
#[derive(Clone, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct ClipmapSettings {
    /// Sample heights through the clipmap (needs `dataset.kind = "tiles"`); off: one texture.
    pub enabled: bool,
    /// Atlas layers (one node each); fixed for the run: the GPU atlas memory budget.
    pub atlas_capacity: u32,
    /// Nodes per side of each level's window in the quadtree (even).
    pub node_count: u32,
    /// Most loads queued or finished-but-not-uploaded at once.
    pub max_in_flight: u32,
    /// Most nodes copied into the atlas per frame (sizes each slot's staging buffer).
    pub max_uploads_per_frame: u32,
    /// Loader threads.
    pub workers: u32,
    /// Frames before a node whose load failed is requested again.
    pub retry_frames: u32,
    /// Width (in nodes of the level) of the band at each window's inner edge over which the
    /// level blends into the next coarser one (0: no blending; steps at ring edges).
    pub blend_nodes: f64,
}

impl Default for ClipmapSettings {
    fn default() -> Self {
        ClipmapSettings {
            enabled: false,
            atlas_capacity: 192,
            node_count: 6,
            max_in_flight: 16,
            max_uploads_per_frame: 8,
            workers: 1,
            retry_frames: 120,
            blend_nodes: 0.5,
        }
    }
}

impl ClipmapSettings {
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::invalid("clipmap", m));
        if !(2..=65535).contains(&self.atlas_capacity) {
            return bad(format!(
                "atlas_capacity {} must be within 2..=65535",
                self.atlas_capacity
            ));
        }
        if !(2..=64).contains(&self.node_count) || self.node_count % 2 != 0 {
            return bad(format!(
                "node_count {} must be even and within 2..=64",
                self.node_count
            ));
        }
        if !(1..=1024).contains(&self.max_in_flight) {
            return bad(format!(
                "max_in_flight {} must be within 1..=1024",
                self.max_in_flight
            ));
        }
        if !(1..=256).contains(&self.max_uploads_per_frame) {
            return bad(format!(
                "max_uploads_per_frame {} must be within 1..=256",
                self.max_uploads_per_frame
            ));
        }
        if !(self.blend_nodes.is_finite() && (0.0..=2.0).contains(&self.blend_nodes)) {
            return bad(format!(
                "blend_nodes {} must be within 0..=2",
                self.blend_nodes
            ));
        }
        if !(1..=16).contains(&self.workers) {
            return bad(format!("workers {} must be within 1..=16", self.workers));
        }
        Ok(())
    }
}

/// A node to copy into the atlas this frame: its layer (heights are the atlas's CPU copy) and
/// its shading planes ([`Geometry::shading`]).
#[derive(Clone, Debug)]
pub struct Upload {
    pub layer: u16,
    pub shading: Vec<u8>,
}

/// What streaming did so far (all counts since creation).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Counters {
    pub requested: u64,
    pub loaded: u64,
    pub uploaded: u64,
    /// Loads that failed (missing/corrupt file, loader error); retried after `retry_frames`.
    pub load_errors: u64,
    /// Requests dropped because no view wanted the node any more (before or after loading).
    pub cancelled: u64,
    /// Node-frames a wanted node was not requested or not stored because every atlas layer
    /// held a wanted node (atlas exhausted).
    pub deferred: u64,
    pub evictions: u64,
    /// Frames in which some quadtree cell of view 0 pointed at a coarser (fallback) node.
    pub fallback_frames: u64,
}

/// The host side of the clipmap.
pub struct Clipmap {
    pub geometry: Geometry,
    pub settings: ClipmapSettings,
    pub atlas: Atlas,
    pub views: Vec<ViewQuadtree>,
    streamer: Streamer,
    frame: u64,
    in_flight: HashSet<NodeKey>,
    ready: VecDeque<(NodeKey, NodeData, Vec<u8>)>,
    failed: HashMap<NodeKey, u64>,
    pending_uploads: Vec<Upload>,
    pub counters: Counters,
    source: Arc<dyn NodeSource>,
}

impl Clipmap {
    /// Creates the atlas and `views` quadtrees, and loads the root level synchronously (set-up
    /// time, pinned), so every lookup has a resident ancestor from the first frame.
    pub fn new(
        geometry: Geometry,
        settings: ClipmapSettings,
        source: Arc<dyn NodeSource>,
        views: usize,
    ) -> Result<Self> {
        settings.validate()?;
        let lods = geometry.levels.len() as u32;
        if lods == 0 || lods > CLIPMAP_MAX_LEVELS {
            return Err(Error::invalid(
                "clipmap",
                format!("{lods} levels, supported 1..={CLIPMAP_MAX_LEVELS}"),
            ));
        }
        let root = NodeKey {
            lod: lods - 1,
            x: 0,
            y: 0,
        };
        if geometry.levels[root.lod as usize] != (1, 1) {
            return Err(Error::invalid(
                "clipmap",
                "the coarsest level must be a single node",
            ));
        }
        let mut atlas = Atlas::new(settings.atlas_capacity, geometry.side());
        let node = source
            .load(root)
            .and_then(|n| geometry.check(root, &n).map(|()| n))
            .map_err(|e| Error::invalid("clipmap root node", e.to_string()))?;
        let shading = geometry.shading(root, &node);
        let layer = atlas
            .allocate(root, 0, true)
            .ok_or_else(|| Error::invalid("clipmap", "atlas has no layer for the root"))?;
        atlas.store(layer, node.heights);
        let streamer = Streamer::new(source.clone(), settings.workers, geometry.clone());
        Ok(Clipmap {
            views: (0..views.max(1))
                .map(|_| ViewQuadtree::new(&geometry, settings.node_count, settings.blend_nodes))
                .collect(),
            geometry,
            settings,
            atlas,
            streamer,
            frame: 0,
            in_flight: HashSet::new(),
            ready: VecDeque::new(),
            failed: HashMap::new(),
            pending_uploads: vec![Upload { layer, shading }],
            counters: Counters::default(),
            source,
        })
    }

    /// Bytes of the GPU atlas, all attachments (the memory budget the configuration fixes).
    pub fn atlas_bytes(&self) -> u64 {
        self.settings.atlas_capacity as u64 * self.layer_bytes()
    }

    /// Bytes of one atlas layer over its attachments: height (R32F), normal and albedo (RGBA8,
    /// with mips).
    pub fn layer_bytes(&self) -> u64 {
        gpu::layer_bytes(&self.geometry)
    }

    /// Tile fetch counters of the source, when it fetches tiles (XYZ).
    pub fn tile_counts(&self) -> Option<crate::dataset::xyz::XyzCounts> {
        self.source.tile_counts()
    }

    /// Loads still queued or waiting for upload.
    pub fn busy(&self) -> usize {
        self.in_flight.len() + self.ready.len()
    }

    /// The four-step update for one frame. `viewers`: one position per view in level-0 sample
    /// units. Returns the atlas layers whose contents changed (to upload this frame, in this
    /// order; their heights are [`Atlas::texel`]'s copy).
    pub fn update(&mut self, viewers: &[DVec2]) -> Vec<Upload> {
        self.frame += 1;
        let frame = self.frame;
        // (1) recentre each view, collect wanted nodes; (2) union over views.
        let wanted = self.recentre_views(viewers, frame);
        self.collect_finished_loads(&wanted, frame);
        // (3) copy finished loads into the atlas, bounded per frame.
        let uploads = self.store_ready_nodes(&wanted, frame);
        self.request_missing_nodes(&wanted, frame);
        // (4) re-point every cell at its best resident node.
        self.resolve_views();
        uploads
    }

    /// Steps (1) and (2): every view recentred on its viewer; the nodes any view wants, each
    /// with its most urgent priority, touched in the atlas and handed to the streamer.
    fn recentre_views(&mut self, viewers: &[DVec2], frame: u64) -> HashMap<NodeKey, (u32, u64)> {
        let mut wanted: HashMap<NodeKey, (u32, u64)> = HashMap::new();
        for (view, &viewer) in self.views.iter_mut().zip(viewers) {
            for (key, prio) in view.recentre(&self.geometry, viewer) {
                let e = wanted.entry(key).or_insert(prio);
                *e = (*e).min(prio);
            }
        }
        for key in wanted.keys() {
            self.atlas.touch(*key, frame);
        }
        self.streamer
            .set_wanted(wanted.keys().copied().collect::<HashSet<_>>());
        wanted
    }

    /// Finished loads (never waits): still wanted ones queued as ready, failures remembered
    /// for retry.
    fn collect_finished_loads(&mut self, wanted: &HashMap<NodeKey, (u32, u64)>, frame: u64) {
        for (key, result) in self.streamer.poll() {
            self.in_flight.remove(&key);
            match result {
                LoadResult::Loaded(node, shading) if wanted.contains_key(&key) => {
                    self.counters.loaded += 1;
                    self.ready.push_back((key, node, shading));
                }
                LoadResult::Loaded(..) | LoadResult::Cancelled => self.counters.cancelled += 1,
                LoadResult::Failed(e) => {
                    self.counters.load_errors += 1;
                    tracing::warn!(
                        "clipmap: node {}/{}/{} failed to load: {e}",
                        key.lod,
                        key.x,
                        key.y
                    );
                    self.failed.insert(key, frame);
                }
            }
        }
    }

    /// Step (3): ready nodes still wanted stored in atlas layers, at most
    /// `max_uploads_per_frame` uploads (those pending from start-up first).
    fn store_ready_nodes(
        &mut self,
        wanted: &HashMap<NodeKey, (u32, u64)>,
        frame: u64,
    ) -> Vec<Upload> {
        let mut uploads = std::mem::take(&mut self.pending_uploads);
        while uploads.len() < self.settings.max_uploads_per_frame as usize {
            let Some((key, node, shading)) = self.ready.pop_front() else {
                break;
            };
            if !wanted.contains_key(&key) {
                self.counters.cancelled += 1;
                continue;
            }
            match self.atlas.allocate(key, frame, false) {
                Some(layer) => {
                    self.atlas.store(layer, node.heights);
                    uploads.push(Upload { layer, shading });
                    self.counters.uploaded += 1;
                }
                None => self.counters.deferred += 1,
            }
        }
        uploads
    }

    /// New requests: coarse first, then near; bounded in flight and by free atlas layers.
    fn request_missing_nodes(&mut self, wanted: &HashMap<NodeKey, (u32, u64)>, frame: u64) {
        let retry = self.settings.retry_frames as u64;
        self.failed.retain(|_, f| frame - *f < retry);
        let mut missing: Vec<(NodeKey, (u32, u64))> = wanted
            .iter()
            .filter(|(k, _)| {
                self.atlas.layer_of(**k).is_none()
                    && !self.in_flight.contains(k)
                    && !self.failed.contains_key(k)
                    && !self.ready.iter().any(|(r, ..)| r == *k)
            })
            .map(|(k, p)| (*k, *p))
            .collect();
        missing.sort_by_key(|(k, p)| (*p, *k));
        let wanted_resident = wanted
            .keys()
            .filter(|k| self.atlas.layer_of(**k).is_some())
            .count();
        let room = (self.atlas.capacity() as usize).saturating_sub(wanted_resident + self.busy());
        let slots = (self.settings.max_in_flight as usize).saturating_sub(self.busy());
        let n = missing.len().min(room).min(slots);
        self.counters.deferred += (missing.len() - missing.len().min(room)) as u64;
        for (key, _) in missing.into_iter().take(n) {
            if self.streamer.request(key) {
                self.in_flight.insert(key);
                self.counters.requested += 1;
            }
        }
    }

    /// Step (4): every view's cells re-pointed at their best resident nodes; the frame's
    /// fallback and eviction counters.
    fn resolve_views(&mut self) {
        for view in &mut self.views {
            view.resolve(&self.geometry, &self.atlas);
        }
        if self.views[0].fallback_cells > 0 {
            self.counters.fallback_frames += 1;
        }
        self.counters.evictions = self.atlas.evictions;
    }

    /// Height in metres at a level-0 sample position as `view` samples it now (what the GPU
    /// returns for the state of the last [`Clipmap::update`]).
    pub fn sample_height(&self, view: usize, p: [f32; 2]) -> f32 {
        self.views
            .get(view)
            .map(|v| v.lookup(&self.geometry, &self.atlas, p))
            .unwrap_or(0.0)
    }
}
