//! Web terrain tiles in the XYZ scheme (Terrarium and Mapbox terrain-RGB PNGs): a `z/x/y.png`
//! directory or an `http(s)://.../{z}/{x}/{y}.png` template, as a `preprocess` input (a
//! bounding box at one zoom) and as a live node store for the clipmap (tiles fetched on the
//! loader threads, cached on disk under a size bound).
//!
//! Placement: tile pixels are squares of EPSG:3857 (Web Mercator) metres by the scheme's
//! definition (`x = -pi R + (px + 0.5) * res`, `y = pi R - (py + 0.5) * res`, `res = 2 pi R /
//! (tile * 2^z)`, `R` the CRS's semi-major axis); longitudes and latitudes go to and from it
//! through PROJ. The level-0 grid is the zoom's pixel grid (row 0 = south); level `l` of the
//! pyramid is zoom `z - l`, whose pixels are exactly the 2x2 cells of level `l - 1` once the
//! grid's west and south edges are aligned to `2^(levels - 1)` pixels.
//!
//! Failures (timeouts, HTTP errors, corrupt PNGs) are counted ([`XyzCounters`]); the clipmap
//! shows coarser data where a node failed and retries later. Bodies are limited in size and
//! PNGs decoded with limits, so a hostile server costs bounded memory.

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::crs::{Crs, Georef, Transform};
use super::manifest::datum;
use super::pyramid::{LayerSet, Layout, Node};
use super::source::{Raster, local_spacing};
use crate::error::{Error, Result};

/// Largest tile body accepted (a 512² RGBA PNG without compression is about 1 MiB).
pub const MAX_TILE_BYTES: u64 = 4 << 20;
/// Tiles per side accepted (256 or 512 pixels).
pub const TILE_SIDES: [u32; 2] = [256, 512];
/// Highest zoom of the scheme vkterrain accepts.
pub const MAX_ZOOM: u32 = 24;

/// How heights are packed into RGB.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Encoding {
    /// `h = R * 256 + G + B / 256 - 32768` (metres; steps of 1/256 m).
    Terrarium,
    /// Mapbox terrain-RGB: `h = -10000 + (R * 65536 + G * 256 + B) * 0.1` (steps of 0.1 m).
    Mapbox,
}

impl Encoding {
    pub fn parse(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().as_str() {
            "terrarium" => Ok(Encoding::Terrarium),
            "mapbox" | "terrain-rgb" | "terrainrgb" => Ok(Encoding::Mapbox),
            other => Err(Error::invalid(
                "--encoding",
                format!("{other:?} is not terrarium or mapbox (terrain-RGB)"),
            )),
        }
    }

    pub fn decode(self, [r, g, b]: [u8; 3]) -> f32 {
        let (r, g, b) = (r as f64, g as f64, b as f64);
        (match self {
            Encoding::Terrarium => r * 256.0 + g + b / 256.0 - 32768.0,
            Encoding::Mapbox => -10000.0 + (r * 65536.0 + g * 256.0 + b) * 0.1,
        }) as f32
    }

    /// The nearest code of `h` metres (clamped to the encoding's range): for making tiles.
    pub fn encode(self, h: f64) -> [u8; 3] {
        let v = match self {
            Encoding::Terrarium => ((h + 32768.0) * 256.0).round(),
            Encoding::Mapbox => ((h + 10000.0) * 10.0).round(),
        }
        .clamp(0.0, 16_777_215.0) as u32;
        [(v >> 16) as u8, (v >> 8) as u8, v as u8]
    }

    /// Height step of the code (metres).
    pub fn quantum(self) -> f64 {
        match self {
            Encoding::Terrarium => 1.0 / 256.0,
            Encoding::Mapbox => 0.1,
        }
    }
}

/// Decodes one tile: a `side x side` RGB(A) 8-bit PNG, into heights row-major from the north.
/// Limits keep hostile input bounded.
pub fn decode_tile(bytes: &[u8], encoding: Encoding, side: u32) -> Result<Vec<f32>> {
    let bad = |m: String| Error::invalid("tile", m);
    if bytes.len() as u64 > MAX_TILE_BYTES {
        return Err(bad(format!("{} bytes is over the limit", bytes.len())));
    }
    let mut reader =
        image::ImageReader::with_format(std::io::Cursor::new(bytes), image::ImageFormat::Png);
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(1024);
    limits.max_image_height = Some(1024);
    limits.max_alloc = Some(16 << 20);
    reader.limits(limits);
    let img = reader
        .decode()
        .map_err(|e| bad(format!("not a decodable PNG: {e}")))?;
    if (img.width(), img.height()) != (side, side) {
        return Err(bad(format!(
            "{}x{} pixels, expected {side}x{side}",
            img.width(),
            img.height()
        )));
    }
    if !matches!(
        img.color(),
        image::ColorType::Rgb8 | image::ColorType::Rgba8
    ) {
        return Err(bad(format!(
            "colour type {:?} is not 8-bit RGB(A): not a terrain tile",
            img.color()
        )));
    }
    let rgb = img.to_rgb8();
    Ok(rgb
        .pixels()
        .map(|p| encoding.decode([p[0], p[1], p[2]]))
        .collect())
}

/// Settings of an XYZ tile source (`[dataset] kind = "xyz"` in a config, `--xyz` flags of preprocess).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct XyzSettings {
    /// `http(s)://host/path/{z}/{x}/{y}.png`, or a directory holding `z/x/y.png` (or a path
    /// template with `{z}`, `{x}`, `{y}`).
    pub source: String,
    pub encoding: Encoding,
    /// West, south, east, north in degrees (WGS84).
    pub bbox: [f64; 4],
    pub zoom: u32,
    /// Pixels per tile side (256 or 512).
    pub tile_size: u32,
    /// On-disk cache of fetched tiles (http sources); none: `$XDG_CACHE_HOME/vkterrain/xyz`
    /// or `~/.cache/vkterrain/xyz`.
    pub cache_dir: Option<PathBuf>,
    /// Bound on the cache's size in MiB (least recently used tiles are deleted beyond it).
    pub cache_max_mb: u64,
    /// Seconds one tile request may take (connect, send, receive) before it counts as failed.
    pub timeout_s: f64,
    /// Pyramid nodes (live source): centre texels per side and border.
    pub node_size: u32,
    pub border: u32,
}

impl Default for XyzSettings {
    fn default() -> Self {
        XyzSettings {
            source: String::new(),
            encoding: Encoding::Terrarium,
            bbox: [0.0; 4],
            zoom: 10,
            tile_size: 256,
            cache_dir: None,
            cache_max_mb: 256,
            timeout_s: 10.0,
            node_size: 256,
            border: 2,
        }
    }
}

/// What `preprocess --xyz` reads.
pub type XyzRequest = XyzSettings;

impl XyzSettings {
    pub fn check(&self) -> Result<()> {
        let bad = |m: String| Err(Error::invalid("xyz", m));
        if self.source.is_empty() {
            return bad("no source (URL template or directory)".into());
        }
        let [w, s, e, n] = self.bbox;
        if !self.bbox.iter().all(|v| v.is_finite())
            || !(-180.0..=180.0).contains(&w)
            || !(-180.0..=180.0).contains(&e)
            || !(-85.05..=85.05).contains(&s)
            || !(-85.05..=85.05).contains(&n)
            || w >= e
            || s >= n
        {
            return bad(format!(
                "bbox {:?} is not west,south,east,north in degrees within the Web Mercator range (|lat| <= 85.05, west < east, south < north)",
                self.bbox
            ));
        }
        if self.zoom > MAX_ZOOM {
            return bad(format!("zoom {} is over {MAX_ZOOM}", self.zoom));
        }
        if !TILE_SIDES.contains(&self.tile_size) {
            return bad(format!("tile_size {} is not 256 or 512", self.tile_size));
        }
        if !(self.timeout_s.is_finite() && self.timeout_s > 0.0 && self.timeout_s <= 600.0) {
            return bad(format!(
                "timeout_s {} is not within 0..600 s",
                self.timeout_s
            ));
        }
        Ok(())
    }

    fn is_http(&self) -> bool {
        self.source.starts_with("http://") || self.source.starts_with("https://")
    }
}

/// Tile fetches and their outcomes, since the source was opened.
#[derive(Debug, Default)]
pub struct XyzCounters {
    /// Requests sent over the network.
    pub fetched: AtomicU64,
    /// Tiles served from the disk cache.
    pub cache_hits: AtomicU64,
    /// Tiles read from a local directory.
    pub local: AtomicU64,
    /// Requests that failed: HTTP status, connection errors, missing files.
    pub errors: AtomicU64,
    /// Requests that timed out.
    pub timeouts: AtomicU64,
    /// Bodies that were not terrain PNGs of the expected size.
    pub corrupt: AtomicU64,
    /// Body bytes received over the network.
    pub bytes: AtomicU64,
    /// Tiles the disk cache deleted to stay within its bound.
    pub evicted: AtomicU64,
}

/// A snapshot of [`XyzCounters`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct XyzCounts {
    pub fetched: u64,
    pub cache_hits: u64,
    pub local: u64,
    pub errors: u64,
    pub timeouts: u64,
    pub corrupt: u64,
    pub bytes: u64,
    pub evicted: u64,
}

impl XyzCounters {
    pub fn snapshot(&self) -> XyzCounts {
        let l = |a: &AtomicU64| a.load(Ordering::Relaxed);
        XyzCounts {
            fetched: l(&self.fetched),
            cache_hits: l(&self.cache_hits),
            local: l(&self.local),
            errors: l(&self.errors),
            timeouts: l(&self.timeouts),
            corrupt: l(&self.corrupt),
            bytes: l(&self.bytes),
            evicted: l(&self.evicted),
        }
    }
}

fn bump(a: &AtomicU64) {
    a.fetch_add(1, Ordering::Relaxed);
}

/// The on-disk tile cache: one file per tile, least recently used deleted beyond the bound.
struct DiskCache {
    dir: PathBuf,
    max_bytes: u64,
    state: Mutex<CacheState>,
}

#[derive(Default)]
struct CacheState {
    files: HashMap<String, (u64, u64)>,
    total: u64,
    tick: u64,
}

impl DiskCache {
    fn open(dir: PathBuf, max_bytes: u64) -> Result<Self> {
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        let mut state = CacheState::default();
        for e in std::fs::read_dir(&dir)
            .map_err(|e| Error::io(&dir, e))?
            .flatten()
        {
            let name = e.file_name().to_string_lossy().to_string();
            if name.ends_with(".png")
                && let Ok(m) = e.metadata()
            {
                state.total += m.len();
                state.files.insert(name, (m.len(), 0));
            }
        }
        Ok(DiskCache {
            dir,
            max_bytes,
            state: Mutex::new(state),
        })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, CacheState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn get(&self, name: &str) -> Option<Vec<u8>> {
        let mut s = self.lock();
        s.tick += 1;
        let tick = s.tick;
        let entry = s.files.get_mut(name)?;
        entry.1 = tick;
        drop(s);
        std::fs::read(self.dir.join(name)).ok()
    }

    /// Stores a tile (temp file + rename) and deletes the least recently used beyond the bound.
    fn put(&self, name: &str, bytes: &[u8], counters: &XyzCounters) {
        let tmp = self
            .dir
            .join(format!("{name}.tmp{:?}", std::thread::current().id()));
        let ok = std::fs::File::create(&tmp)
            .and_then(|mut f| f.write_all(bytes))
            .and_then(|()| std::fs::rename(&tmp, self.dir.join(name)));
        if ok.is_err() {
            let _ = std::fs::remove_file(&tmp);
            return;
        }
        let mut s = self.lock();
        s.tick += 1;
        let tick = s.tick;
        if let Some((old, _)) = s.files.insert(name.to_string(), (bytes.len() as u64, tick)) {
            s.total -= old;
        }
        s.total += bytes.len() as u64;
        while s.total > self.max_bytes {
            let Some(victim) = s
                .files
                .iter()
                .filter(|(k, _)| k.as_str() != name)
                .min_by_key(|(_, v)| v.1)
                .map(|(k, _)| k.clone())
            else {
                break;
            };
            if let Some((size, _)) = s.files.remove(&victim) {
                s.total -= size;
                let _ = std::fs::remove_file(self.dir.join(&victim));
                bump(&counters.evicted);
            }
        }
    }

    fn bytes(&self) -> u64 {
        self.lock().total
    }
}

/// Fetches tiles from a template or directory, through the disk cache.
pub struct TileFetcher {
    settings: XyzSettings,
    agent: Option<ureq::Agent>,
    cache: Option<DiskCache>,
    pub counters: XyzCounters,
}

fn default_cache_root() -> PathBuf {
    std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .unwrap_or_else(std::env::temp_dir)
        .join("vkterrain/xyz")
}

/// FNV-1a of the source (the cache's subdirectory: one per server and path).
fn source_key(s: &str) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in s.bytes() {
        h ^= b as u64;
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    format!("{h:016x}")
}

impl TileFetcher {
    pub fn new(settings: &XyzSettings) -> Result<Self> {
        settings.check()?;
        let (agent, cache) = if settings.is_http() {
            let t = Duration::from_secs_f64(settings.timeout_s);
            let config = ureq::Agent::config_builder()
                .timeout_global(Some(t))
                .timeout_connect(Some(t.min(Duration::from_secs(5))))
                .http_status_as_error(false)
                .build();
            let root = settings
                .cache_dir
                .clone()
                .unwrap_or_else(default_cache_root);
            let cache = DiskCache::open(
                root.join(source_key(&settings.source)),
                settings.cache_max_mb.saturating_mul(1 << 20),
            )?;
            (Some(ureq::Agent::new_with_config(config)), Some(cache))
        } else {
            let dir = Path::new(&settings.source);
            if !settings.source.contains("{z}") && !dir.is_dir() {
                return Err(Error::invalid(
                    &settings.source,
                    "is neither an http(s) URL template nor a directory of z/x/y.png tiles",
                ));
            }
            (None, None)
        };
        Ok(TileFetcher {
            settings: settings.clone(),
            agent,
            cache,
            counters: XyzCounters::default(),
        })
    }

    fn url(&self, z: u32, x: u32, y: u32) -> String {
        let t = if self.settings.is_http() || self.settings.source.contains("{z}") {
            self.settings.source.clone()
        } else {
            format!("{}/{{z}}/{{x}}/{{y}}.png", self.settings.source)
        };
        t.replace("{z}", &z.to_string())
            .replace("{x}", &x.to_string())
            .replace("{y}", &y.to_string())
    }

    /// Bytes the disk cache holds now.
    pub fn cache_bytes(&self) -> u64 {
        self.cache.as_ref().map_or(0, |c| c.bytes())
    }

    /// One tile's heights (row-major from the north); every failure is counted.
    pub fn tile(&self, z: u32, x: u32, y: u32) -> Result<Vec<f32>> {
        let what = format!("tile {z}/{x}/{y}");
        let name = format!("{z}-{x}-{y}.png");
        let (bytes, from_net) = match (&self.agent, &self.cache) {
            (Some(agent), cache) => match cache.as_ref().and_then(|c| c.get(&name)) {
                Some(b) => {
                    bump(&self.counters.cache_hits);
                    (b, false)
                }
                None => (self.get(agent, z, x, y, &what)?, true),
            },
            (None, _) => {
                let path = self.url(z, x, y);
                let meta = std::fs::metadata(&path).map_err(|e| {
                    bump(&self.counters.errors);
                    Error::invalid(&what, format!("{path}: {e}"))
                })?;
                if !meta.is_file() || meta.len() > MAX_TILE_BYTES {
                    bump(&self.counters.corrupt);
                    return Err(Error::invalid(
                        &what,
                        format!("{path} is not a tile file of at most {MAX_TILE_BYTES} bytes"),
                    ));
                }
                bump(&self.counters.local);
                let b = std::fs::read(&path).map_err(|e| {
                    bump(&self.counters.errors);
                    Error::invalid(&what, format!("{path}: {e}"))
                })?;
                (b, false)
            }
        };
        let heights = decode_tile(&bytes, self.settings.encoding, self.settings.tile_size)
            .map_err(|e| {
                bump(&self.counters.corrupt);
                Error::invalid(&what, e.to_string())
            })?;
        if from_net && let Some(c) = &self.cache {
            c.put(&name, &bytes, &self.counters);
        }
        Ok(heights)
    }

    fn get(&self, agent: &ureq::Agent, z: u32, x: u32, y: u32, what: &str) -> Result<Vec<u8>> {
        let url = self.url(z, x, y);
        bump(&self.counters.fetched);
        let fail = |e: ureq::Error| {
            if matches!(e, ureq::Error::Timeout(_)) {
                bump(&self.counters.timeouts);
            } else {
                bump(&self.counters.errors);
            }
            Error::invalid(what, format!("{url}: {e}"))
        };
        let mut resp = agent.get(&url).call().map_err(fail)?;
        let status = resp.status().as_u16();
        if status != 200 {
            bump(&self.counters.errors);
            return Err(Error::invalid(what, format!("{url}: HTTP status {status}")));
        }
        let body = resp
            .body_mut()
            .with_config()
            .limit(MAX_TILE_BYTES)
            .read_to_vec()
            .map_err(fail)?;
        self.counters
            .bytes
            .fetch_add(body.len() as u64, Ordering::Relaxed);
        Ok(body)
    }

    /// [`TileFetcher::tile`] with up to `attempts` tries (a short pause between).
    pub fn tile_retrying(&self, z: u32, x: u32, y: u32, attempts: u32) -> Result<Vec<f32>> {
        let mut last = None;
        for k in 0..attempts.max(1) {
            match self.tile(z, x, y) {
                Ok(t) => return Ok(t),
                Err(e) => last = Some(e),
            }
            if k + 1 < attempts {
                std::thread::sleep(Duration::from_millis(200 << k));
            }
        }
        Err(last.expect("one attempt"))
    }
}

/// The pixel grid of a bounding box at one zoom: pixels `[px0, px1) x [py0, py1)` (rows from
/// the north), with Web Mercator placement.
#[derive(Clone, Debug, PartialEq)]
pub struct XyzGrid {
    pub zoom: u32,
    pub tile: u32,
    pub px0: u64,
    pub px1: u64,
    pub py0: u64,
    pub py1: u64,
    /// Semi-major axis of EPSG:3857 (metres).
    pub radius: f64,
}

impl XyzGrid {
    /// The pixels whose centres cover `bbox`, with the west and south edges aligned to
    /// multiples of `align` pixels (1: no alignment).
    pub fn cover(s: &XyzSettings, align: u64) -> Result<Self> {
        s.check()?;
        let merc = Crs::web_mercator()?;
        let to = Transform::new(&Crs::wgs84()?, &merc)?;
        let radius = semi_major(&merc)?;
        let [w, so, e, n] = s.bbox;
        let sw = to.point([w, so])?;
        let ne = to.point([e, n])?;
        let pixels = (s.tile_size as u64) << s.zoom;
        let res = 2.0 * std::f64::consts::PI * radius / pixels as f64;
        let half = std::f64::consts::PI * radius;
        let px = |x: f64| (x + half) / res;
        let py = |y: f64| (half - y) / res;
        let clamp = |v: f64| v.clamp(0.0, pixels as f64) as u64;
        let mut px0 = clamp(px(sw[0]).floor());
        let px1 = clamp(px(ne[0]).ceil()).max(px0 + 2);
        let py0 = clamp(py(ne[1]).floor());
        let mut py1 = clamp(py(sw[1]).ceil()).max(py0 + 2);
        px0 -= px0 % align;
        if py1 % align != 0 {
            py1 += align - py1 % align;
        }
        if px1 > pixels || py1 > pixels {
            return Err(Error::invalid(
                "xyz",
                format!(
                    "bbox {:?} at zoom {} cannot be aligned inside the world",
                    s.bbox, s.zoom
                ),
            ));
        }
        Ok(XyzGrid {
            zoom: s.zoom,
            tile: s.tile_size,
            px0,
            px1,
            py0,
            py1,
            radius,
        })
    }

    pub fn width(&self) -> u64 {
        self.px1 - self.px0
    }

    pub fn height(&self) -> u64 {
        self.py1 - self.py0
    }

    /// EPSG:3857 metres per pixel at this zoom.
    pub fn resolution(&self) -> f64 {
        2.0 * std::f64::consts::PI * self.radius / ((self.tile as u64) << self.zoom) as f64
    }

    /// The level-0 grid in EPSG:3857: sample `(col, row)` (row 0 = south) is the centre of
    /// pixel `(px0 + col, py1 - 1 - row)`.
    pub fn georef(&self) -> Result<Georef> {
        let res = self.resolution();
        let half = std::f64::consts::PI * self.radius;
        Ok(Georef::north_up(
            Crs::web_mercator()?,
            [
                -half + (self.px0 as f64 + 0.5) * res,
                half - (self.py1 as f64 - 0.5) * res,
            ],
            [res, res],
        ))
    }
}

/// The semi-major axis of a CRS's ellipsoid (PROJ).
#[cfg(feature = "gdal")]
fn semi_major(crs: &Crs) -> Result<f64> {
    crs.spatial_ref()?
        .semi_major()
        .map_err(|e| Error::invalid(crs.label(), e.to_string()))
}

#[cfg(not(feature = "gdal"))]
fn semi_major(crs: &Crs) -> Result<f64> {
    Err(Error::invalid(crs.label(), "built without GDAL/PROJ"))
}

/// Tiles of `grid` fetched in parallel and pasted into a raster (row 0 = south).
pub fn read_raster(s: &XyzSettings, memory_budget: Option<u64>) -> Result<(Raster, u64)> {
    let fetcher = TileFetcher::new(s)?;
    let grid = XyzGrid::cover(s, 1)?;
    let (w, h) = (grid.width(), grid.height());
    let name = format!("XYZ {} z{} {:?}", s.source, s.zoom, s.bbox);
    let need = w * h * super::source::BYTES_PER_SAMPLE;
    let have = memory_budget
        .or_else(super::output::available_memory)
        .unwrap_or(u64::MAX);
    if w > super::pyramid::MAX_SIDE_SAMPLES || h > super::pyramid::MAX_SIDE_SAMPLES || need > have {
        return Err(Error::invalid(
            &name,
            format!(
                "{w}x{h} samples need {} of memory, {} available: choose a smaller bbox or zoom",
                super::output::human_bytes(need),
                super::output::human_bytes(have)
            ),
        ));
    }
    let t = grid.tile as u64;
    let tiles: Vec<(u64, u64)> = (grid.py0 / t..=(grid.py1 - 1) / t)
        .flat_map(|ty| (grid.px0 / t..=(grid.px1 - 1) / t).map(move |tx| (tx, ty)))
        .collect();
    let (wu, hu) = (w as usize, h as usize);
    let heights = Mutex::new(vec![f32::NAN; wu * hu]);
    tiles.par_iter().try_for_each(|&(tx, ty)| -> Result<()> {
        let tile = fetcher.tile_retrying(grid.zoom, tx as u32, ty as u32, 3)?;
        let mut out = heights.lock().unwrap_or_else(|e| e.into_inner());
        for j in 0..t {
            let py = ty * t + j;
            if py < grid.py0 || py >= grid.py1 {
                continue;
            }
            let row = (grid.py1 - 1 - py) as usize;
            for i in 0..t {
                let px = tx * t + i;
                if px < grid.px0 || px >= grid.px1 {
                    continue;
                }
                out[row * wu + (px - grid.px0) as usize] = tile[(j * t + i) as usize];
            }
        }
        Ok(())
    })?;
    let heights = heights.into_inner().unwrap_or_else(|e| e.into_inner());
    let georef = grid.georef()?;
    let (spacing, warning) = local_spacing(&georef, w as u32, h as u32)?;
    let c = fetcher.counters.snapshot();
    let raster = Raster {
        name,
        width: w as u32,
        height: h as u32,
        spacing,
        heights,
        georef: Some(georef),
        vertical_datum: datum::UNKNOWN.into(),
        nodata: None,
        provenance: vec![format!(
            "XYZ tiles {} ({:?}, zoom {}, {} tiles of {}x{} px: {} fetched, {} from cache, {} local), bbox {:?} deg -> pixels {}..{} x {}..{} (EPSG:3857 placement through PROJ)",
            s.source,
            s.encoding,
            s.zoom,
            tiles.len(),
            s.tile_size,
            s.tile_size,
            c.fetched,
            c.cache_hits,
            c.local,
            s.bbox,
            grid.px0,
            grid.px1,
            grid.py0,
            grid.py1
        )],
        warnings: warning.into_iter().collect(),
    };
    Ok((raster, c.bytes))
}

/// A decoded tile (heights row-major from the north).
type Tile = Arc<Vec<f32>>;

/// Decoded tiles shared by nodes (a node needs up to 3x3 tiles): `(zoom, x, y)` -> (tile,
/// last use).
struct TileCache {
    tiles: HashMap<(u32, u64, u64), (Tile, u64)>,
    tick: u64,
}

/// XYZ tiles as a live tile pyramid: node `(lod, x, y)` is read from zoom `zoom - lod`.
pub struct XyzPyramid {
    pub settings: XyzSettings,
    pub fetcher: TileFetcher,
    pub grid: XyzGrid,
    pub layout: Layout,
    /// Local metres between level-0 samples (square: Web Mercator pixels are square).
    pub spacing: f64,
    pub height_range: [f32; 2],
    cache: Mutex<TileCache>,
}

/// Decoded tiles kept in memory.
const TILE_CACHE: usize = 64;

impl XyzPyramid {
    pub fn open(s: &XyzSettings) -> Result<Self> {
        let fetcher = TileFetcher::new(s)?;
        // Levels depend on the grid, the alignment on the levels: iterate to a fixed point.
        let mut align = 1u64;
        let (grid, layout) = loop {
            let grid = XyzGrid::cover(s, align)?;
            let layout = Layout::new(grid.width(), grid.height(), s.node_size, s.border)?;
            let need = 1u64 << (layout.levels() - 1);
            if need <= align {
                break (grid, layout);
            }
            align = need;
        };
        let levels = layout.levels();
        if levels - 1 > s.zoom {
            return Err(Error::invalid(
                "xyz",
                format!(
                    "the pyramid needs {levels} levels but zoom {} has only {} coarser zooms: raise the zoom or node_size",
                    s.zoom, s.zoom
                ),
            ));
        }
        let georef = grid.georef()?;
        let (sp, _) = local_spacing(&georef, grid.width() as u32, grid.height() as u32)?;
        let mut p = XyzPyramid {
            settings: s.clone(),
            fetcher,
            spacing: sp[1],
            grid,
            layout,
            height_range: [0.0, 0.0],
            cache: Mutex::new(TileCache {
                tiles: HashMap::new(),
                tick: 0,
            }),
        };
        // The root node gives the colour ramp's range (retrying: start-up may wait).
        let root = (0..3)
            .map(|k| {
                if k > 0 {
                    std::thread::sleep(Duration::from_millis(300));
                }
                p.node_heights(levels - 1, 0, 0)
            })
            .find(|r| r.is_ok())
            .unwrap_or_else(|| p.node_heights(levels - 1, 0, 0))
            .map_err(|e| Error::invalid("xyz root node", e.to_string()))?;
        let (lo, hi) = root
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        p.height_range = [lo, hi.max(lo + 1.0)];
        Ok(p)
    }

    fn tile(&self, zoom: u32, tx: u64, ty: u64) -> Result<Tile> {
        {
            let mut c = self.cache.lock().unwrap_or_else(|e| e.into_inner());
            c.tick += 1;
            let tick = c.tick;
            if let Some(e) = c.tiles.get_mut(&(zoom, tx, ty)) {
                e.1 = tick;
                return Ok(e.0.clone());
            }
        }
        let t = Arc::new(self.fetcher.tile(zoom, tx as u32, ty as u32)?);
        let mut c = self.cache.lock().unwrap_or_else(|e| e.into_inner());
        if c.tiles.len() >= TILE_CACHE
            && let Some(k) = c.tiles.iter().min_by_key(|(_, v)| v.1).map(|(k, _)| *k)
        {
            c.tiles.remove(&k);
        }
        let tick = c.tick;
        c.tiles.insert((zoom, tx, ty), (t.clone(), tick));
        Ok(t)
    }

    /// Node `(lod, x, y)`'s `side x side` heights (borders included, row 0 = south).
    pub fn node_heights(&self, lod: u32, x: u32, y: u32) -> Result<Vec<f32>> {
        let l = &self.layout;
        let (nx, ny) = l.nodes(lod);
        if lod >= l.levels() || x >= nx || y >= ny {
            return Err(Error::invalid(
                "xyz",
                format!("node {lod}/{x}/{y} outside the pyramid"),
            ));
        }
        let (w, h) = l.level_size(lod);
        let zoom = self.grid.zoom - lod;
        let (px0, py1) = (self.grid.px0 >> lod, self.grid.py1 >> lod);
        let t = self.grid.tile as u64;
        let idx = |n: u32, k: i64, len: u64| {
            (n as i64 * l.center as i64 + k - l.border as i64).clamp(0, len as i64 - 1) as u64
        };
        let side = l.side() as i64;
        let mut out = Vec::with_capacity((side * side) as usize);
        let mut current: Option<((u64, u64), Tile)> = None;
        for j in 0..side {
            let py = py1 - 1 - idx(y, j, h);
            for i in 0..side {
                let px = px0 + idx(x, i, w);
                let key = (px / t, py / t);
                let tile = match &current {
                    Some((k, tile)) if *k == key => tile.clone(),
                    _ => {
                        let tile = self.tile(zoom, key.0, key.1)?;
                        current = Some((key, tile.clone()));
                        tile
                    }
                };
                out.push(tile[((py % t) * t + px % t) as usize]);
            }
        }
        Ok(out)
    }

    /// Reads a node as the pyramid's stores do.
    pub fn read_node(&self, lod: u32, x: u32, y: u32) -> Result<Node> {
        let heights = self.node_heights(lod, x, y)?;
        let (lo, hi) = heights
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        Ok(Node {
            min: lo,
            max: hi,
            filled: 0,
            heights,
            mask: Vec::new(),
            rgba: Vec::new(),
        })
    }

    pub fn layers(&self) -> LayerSet {
        LayerSet::default()
    }

    pub fn name(&self) -> String {
        format!(
            "XYZ {} z{} {:?} ({:?}, live)",
            self.settings.source, self.settings.zoom, self.settings.bbox, self.settings.encoding
        )
    }
}
