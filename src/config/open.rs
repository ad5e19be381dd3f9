//! Opening what a configuration names: the device, the data set (the whole grid, or with the
//! clipmap a tile pyramid read node by node), the clipmap, the scenario and the renderer. Every
//! command and benchmark goes through these, so a setting means the same thing everywhere.

use std::path::Path;
use std::sync::Arc;

use super::Config;
use crate::clipmap::{Clipmap, Geometry, StoreSource};
use crate::dataset::{NodeStore, PyramidReader, Terrain};
use crate::driver::Gpu;
use crate::error::Result;
use crate::render::{RenderOptions, Renderer};
use crate::scene::Scenario;

impl Config {
    /// The device `[device]` selects (`VKTERRAIN_DEVICE` and `VKTERRAIN_VALIDATION` win).
    pub fn open_gpu(&self) -> Result<Arc<Gpu>> {
        Gpu::new(&self.device.clone().with_env())
    }

    /// The data set's level 0: the whole grid in memory, or with `[clipmap] enabled` the tile
    /// pyramid read node by node (level 0 is then never held whole on the host).
    pub fn open_terrain(&self) -> Result<Terrain> {
        if self.clipmap.enabled {
            Ok(Terrain::Pyramid(Arc::new(PyramidReader::from_store(
                self.open_store()?,
            )?)))
        } else {
            Ok(Terrain::Grid(Arc::new(
                self.dataset.load(|p| self.resolve(p))?,
            )))
        }
    }

    /// The clipmap `[clipmap]` asks for, with a quadtree per camera of a frame; `None` when
    /// disabled.
    pub fn open_clipmap(&self) -> Result<Option<Clipmap>> {
        if !self.clipmap.enabled {
            return Ok(None);
        }
        let store = self.open_store()?;
        let geometry = Geometry::of_store(&*store);
        Clipmap::new(
            geometry,
            self.clipmap.clone(),
            Arc::new(StoreSource(store)),
            self.render.views(),
        )
        .map(Some)
    }

    /// The renderer's options (`[render]`).
    pub fn render_options(&self) -> RenderOptions {
        self.render.options()
    }

    /// The renderer this configuration describes, over `data` (from [`Config::open_terrain`]),
    /// with `options` (usually [`Config::render_options`], possibly changed by a command).
    pub fn open_renderer(
        &self,
        gpu: &Arc<Gpu>,
        data: &Terrain,
        options: RenderOptions,
    ) -> Result<Renderer> {
        let lattice = geo_anchor_from_env(data)?;
        Renderer::with_world(
            gpu,
            data.clone(),
            self.method.clone(),
            options,
            self.open_clipmap()?,
            lattice.as_ref(),
        )
    }

    /// The scenario file `path` (or the configured one, or the built-in default flight)
    /// resolved against `data`.
    pub fn open_scenario(&self, path: Option<&Path>, data: &Terrain) -> Result<Scenario> {
        let configured = self.scenario.path.as_ref().map(|p| self.resolve(p));
        match path.map(Path::to_path_buf).or(configured) {
            Some(path) => Scenario::load(&path, data),
            None => Scenario::builtin_default(data),
        }
    }

    /// The data set's node store (`tiles` or `xyz`), read node by node.
    pub fn open_store(&self) -> Result<Arc<dyn NodeStore>> {
        self.dataset.open_store(|p| self.resolve(p))
    }
}

/// Until the data set's world frame (issue 14a: georeference or `[dataset] anchor`) reaches
/// the renderer: `VKTERRAIN_GEO_ANCHOR="LAT,LON"` (degrees) places a local data set on the
/// ellipsoid at that anchor (`Lattice::anchored_plane`), for benchmarks of the geodetic
/// mapping against the flat one (scripts/device/geodetic.sh).
fn geo_anchor_from_env(data: &Terrain) -> Result<Option<crate::geo::Lattice>> {
    use crate::dataset::Level0;
    let Ok(text) = std::env::var("VKTERRAIN_GEO_ANCHOR") else {
        return Ok(None);
    };
    let bad = || {
        crate::error::Error::invalid(
            "VKTERRAIN_GEO_ANCHOR",
            format!("{text:?} is not LAT,LON in degrees"),
        )
    };
    let (lat, lon) = text.split_once(',').ok_or_else(bad)?;
    let lat: f64 = lat.trim().parse().map_err(|_| bad())?;
    let lon: f64 = lon.trim().parse().map_err(|_| bad())?;
    if !(lat.abs() < 90.0 && lon.abs() <= 180.0) {
        return Err(bad());
    }
    let frame =
        crate::geo::EnuFrame::new(&crate::geo::WGS84, crate::geo::Geodetic::new(lat, lon, 0.0));
    crate::geo::Lattice::anchored_plane(data.width(), data.height(), data.spacing(), frame)
        .map(Some)
}
