//! Opening what a configuration names: the device, the data set (the whole grid, or with the
//! clipmap a tile pyramid read node by node), the clipmap, the scenario and the renderer. Every
//! command and benchmark goes through these, so a setting means the same thing everywhere.

use std::path::Path;
use std::sync::Arc;

use super::Config;
use crate::clipmap::{Clipmap, DatasetSource, Geometry};
use crate::dataset::{PyramidReader, Terrain};
use crate::driver::Gpu;
use crate::error::{Error, Result};
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
            Ok(Terrain::Pyramid(Arc::new(PyramidReader::open(
                &self.pyramid_dir()?,
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
        let source = DatasetSource::open(&self.pyramid_dir()?)?;
        let geometry = Geometry::of(&source.dataset);
        Clipmap::new(
            geometry,
            self.clipmap.clone(),
            Arc::new(source),
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
        Renderer::with_clipmap(
            gpu,
            data.clone(),
            self.method.clone(),
            options,
            self.open_clipmap()?,
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

    fn pyramid_dir(&self) -> Result<std::path::PathBuf> {
        self.dataset
            .tiles_path()
            .map(|p| self.resolve(p))
            .ok_or_else(|| Error::invalid("dataset", "the clipmap needs a tiles data set"))
    }
}
