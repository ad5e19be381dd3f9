//! The earth as vkterrain models it, in f64 on the CPU: the WGS84 ellipsoid, earth-centred
//! earth-fixed (ECEF) coordinates and local east-north-up (ENU) tangent frames.
//!
//! A low layer: no GPU, no data set, no PROJ. CRS transformations of data sets go through PROJ
//! (`dataset::crs`); this module holds the one thing every layer needs without PROJ (the
//! GPU machine's builds have no GDAL): the ellipsoid's own geometry, whose closed forms define
//! WGS84 and are proven equal to PROJ's `EPSG:4979 -> EPSG:4978` in a test.

pub mod ellipsoid;
pub mod frame;
pub mod lattice;
pub mod pose;

pub use ellipsoid::{Geodetic, WGS84};
pub use frame::EnuFrame;
pub use lattice::{EarthCull, Lattice, WorldBox, is_square};
pub use pose::{GeoPose, HeightRef, WorldPose};
