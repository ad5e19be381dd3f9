//! Opening what a configuration names: the device, the data set (the whole grid, or with the
//! clipmap a tile pyramid read node by node), the clipmap, the scenario and the renderer. Every
//! command and benchmark goes through these, so a setting means the same thing everywhere.

use std::path::Path;
use std::sync::Arc;

use super::Config;
use crate::clipmap::{Clipmap, Geometry, StoreSource};
use crate::dataset::tiles::LoadGrid;
use crate::dataset::world::Placement;
use crate::dataset::{NodeStore, PyramidReader, Terrain};
use crate::driver::Gpu;
use crate::error::Result;
use crate::geo::{EnuFrame, Lattice};
use crate::output::ring::layout::{DATUM_ELLIPSOID, datum_code};
use crate::render::{EarthGeometry, RenderOptions, Renderer};
use crate::scene::{Earth, Scenario};

impl Config {
    /// The device `[device]` selects (`VKTERRAIN_DEVICE` and `VKTERRAIN_VALIDATION` win).
    pub fn open_gpu(&self) -> Result<Arc<Gpu>> {
        Gpu::new(&self.device.clone().with_env())
    }

    /// The data set's level 0: the whole grid in memory, or with `[clipmap] enabled` the tile
    /// pyramid read node by node (level 0 is then never held whole on the host).
    pub fn open_terrain(&self) -> Result<Terrain> {
        let grid = self.load_grid();
        if self.clipmap.enabled {
            Ok(Terrain::Pyramid(Arc::new(PyramidReader::from_store_as(
                self.open_store()?,
                grid,
            )?)))
        } else {
            Ok(Terrain::Grid(Arc::new(
                self.dataset.load_as(|p| self.resolve(p), grid)?,
            )))
        }
    }

    /// The clipmap `[clipmap]` asks for, with a quadtree per camera of a frame; `None` when
    /// disabled. `lattice`: the one the renderer draws through on the earth (the shading
    /// planes' normals are then in world axes), None in the flat world.
    pub fn open_clipmap(&self, lattice: Option<Arc<Lattice>>) -> Result<Option<Clipmap>> {
        if !self.clipmap.enabled {
            return Ok(None);
        }
        let store = self.open_store()?;
        let mut geometry = Geometry::of_store(&*store).with_world(lattice);
        if self.load_grid() == LoadGrid::Native {
            geometry = geometry.with_native_spacing(store.georef()?.as_ref());
        }
        Clipmap::new(
            geometry,
            self.clipmap.clone(),
            Arc::new(StoreSource(store)),
            self.render.views(),
        )
        .map(Some)
    }

    /// How a non-square (geographic) grid is loaded: on the ellipsoid every native sample is
    /// drawn where it lies (the lattice); the flat world needs square metres.
    fn load_grid(&self) -> LoadGrid {
        match self.render.earth {
            EarthGeometry::Ellipsoid => LoadGrid::Native,
            EarthGeometry::Flat => LoadGrid::SquareMetres,
        }
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
        let placement = self.dataset.placement(|p| self.resolve(p))?;
        let lattice = Self::lattice_of(placement.as_ref(), data, options.earth)?.map(Arc::new);
        let mut renderer = Renderer::with_world(
            gpu,
            data.clone(),
            self.method.clone(),
            options,
            self.open_clipmap(lattice.clone())?,
            lattice.as_deref(),
        )?;
        // The frames' camera heights: above the ellipsoid where the lattice carries the
        // terrain's datum (world heights are ellipsoidal there), else in the terrain's datum.
        renderer.world = placement.map(|p| {
            let code = match &lattice {
                Some(_) if p.lattice_on_datum() => DATUM_ELLIPSOID,
                _ => datum_code(&p.vertical_datum),
            };
            (p.frame, code)
        });
        Ok(renderer)
    }

    /// The geolocation lattice a renderer with `earth` draws `data` through (None: the flat
    /// world: no world frame, or `earth = "flat"`).
    pub fn open_lattice(&self, data: &Terrain, earth: EarthGeometry) -> Result<Option<Lattice>> {
        let placement = self.dataset.placement(|p| self.resolve(p))?;
        Self::lattice_of(placement.as_ref(), data, earth)
    }

    fn lattice_of(
        placement: Option<&Placement>,
        data: &Terrain,
        earth: EarthGeometry,
    ) -> Result<Option<Lattice>> {
        match (placement, earth) {
            (Some(p), EarthGeometry::Ellipsoid) => p.lattice(data).map(Some),
            _ => Ok(None),
        }
    }

    /// The scenario file `path` (or the configured one, or the built-in default flight)
    /// resolved against `data`.
    pub fn open_scenario(&self, path: Option<&Path>, data: &Terrain) -> Result<Scenario> {
        let configured = self.scenario.path.as_ref().map(|p| self.resolve(p));
        // On the ellipsoid, keyframes given on the grid are placed over their samples there.
        let on_earth = self.render.earth == EarthGeometry::Ellipsoid;
        match path.map(Path::to_path_buf).or(configured) {
            Some(path) => Scenario::load_on(&path, data, || self.open_earth(), on_earth),
            None if on_earth => Scenario::builtin_default_on(data, self.open_earth()?.as_ref()),
            None => Scenario::builtin_default(data),
        }
    }

    /// Where the world lies on the earth: the east-north-up frame at the data set's sample
    /// (0, 0) (georeferenced data, or `[dataset] anchor`); `None`: a flat world.
    pub fn world_frame(&self) -> Result<Option<EnuFrame>> {
        self.dataset.world_frame(|p| self.resolve(p))
    }

    /// The data set's place on the earth, for poses given by latitude/longitude; `None`: a flat
    /// world.
    pub fn open_earth(&self) -> Result<Option<Earth>> {
        let on_lattice = self.render.earth == EarthGeometry::Ellipsoid;
        Ok(self.dataset.placement(|p| self.resolve(p))?.map(|p| {
            if on_lattice {
                Earth::on_lattice(p)
            } else {
                Earth::new(p)
            }
        }))
    }

    /// The data set's node store (`tiles` or `xyz`), read node by node.
    pub fn open_store(&self) -> Result<Arc<dyn NodeStore>> {
        self.dataset.open_store(|p| self.resolve(p))
    }
}
