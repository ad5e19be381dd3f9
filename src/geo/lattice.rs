//! The geolocation lattice: where the terrain's samples lie in the world frame, for the GPU.
//!
//! Every `step`-th sample (and one node past the last sample on each axis) the CPU computes in
//! f64 the world-frame position of the sample at height 0 of the data set's vertical datum
//! (the ellipsoid point, lifted along the normal by the datum's height above the ellipsoid:
//! the geoid undulation `N` for heights above mean sea level, [`Lattice::on_datum`]; 0 for
//! ellipsoidal and local heights) and the unit up vector there (the ellipsoid normal, rotated
//! into the world frame). A sample of height `h` then lies at ellipsoidal height `h + N`,
//! with `N` bilinear between nodes. Positions are stored
//! as split doubles (`hi = f32(p)`, `lo = f32(p - hi)`) relative to the world origin. The vertex
//! shaders (`relative_position` in `shaders/include/terrain_common.wgsl` and its GLSL port)
//! interpolate the lattice bilinearly at the sample position, add `height * up` and subtract
//! the camera's split position (hi - hi, then lo - lo), so camera-relative positions keep f32
//! precision anywhere. [`Lattice::position`] is the CPU mirror: the same lattice data and the
//! same formula, in f64. docs/coordinates.md ("Geodetic geometry") derives the error budget.

use std::sync::Arc;

use glam::{DVec2, DVec3};

use super::ellipsoid::{Geodetic, WGS84};
use super::frame::EnuFrame;
use crate::error::{Error, Result};
use crate::gpu_constants::GEO_MIN_RADIUS;

/// Largest lattice cell side (metres) [`Lattice::step_for`] aims for: the sagitta of the
/// diagonal, `(sqrt(2) * 500)^2 / (8 * 6.3e6)`, is 1.0 cm.
pub const CELL_M: f64 = 500.0;

/// Floats per lattice node on the GPU: three vec4 (hi.xyz, lo.xyz, up.xyz; w unused).
pub const NODE_FLOATS: usize = 12;

/// Where the samples of a grid lie on the ellipsoid, every `step` samples.
#[derive(Clone, Debug, PartialEq)]
pub struct Lattice {
    /// Samples between lattice nodes on both axes.
    pub step: u32,
    /// Nodes per row and per column; node `(i, j)` is sample `(i * step, j * step)`.
    pub nodes: [u32; 2],
    /// The world frame the positions are in.
    pub frame: EnuFrame,
    /// World positions (f64, height 0 of the datum) and unit up vectors, row-major.
    positions: Vec<DVec3>,
    ups: Vec<DVec3>,
    /// A lower bound (metres, an f32 value) of the radius of curvature of the surface and of
    /// the grid's lines on it: culling boxes grow by a curve's sagitta over it
    /// ([`Lattice::rect_box`]).
    curve_radius: f64,
    /// Each node's geodetic latitude/longitude (degrees) and the datum's height above the
    /// ellipsoid there (metres; 0 until [`Lattice::on_datum`]).
    lat_lon: Vec<[f64; 2]>,
    datum: Vec<f64>,
}

/// The ellipsoid normal (unit, ECEF) at a geodetic latitude/longitude.
pub fn normal_ecef(lat_deg: f64, lon_deg: f64) -> DVec3 {
    let (sl, cl) = lat_deg.to_radians().sin_cos();
    let (so, co) = lon_deg.to_radians().sin_cos();
    DVec3::new(cl * co, cl * so, sl)
}

/// Splits an f64 into the f32 pair `(hi, lo)` with `hi + lo` within ~1e-14 relative of it.
pub fn split(v: DVec3) -> ([f32; 3], [f32; 3]) {
    let hi = v.as_vec3();
    let lo = (v - hi.as_dvec3()).as_vec3();
    (hi.to_array(), lo.to_array())
}

/// The smallest radius of curvature of a grid on the ellipsoid up to latitude `max_lat_deg`,
/// rounded down to an f32 (the GPU's copy is the same number): the surface curves with radius
/// at least [`GEO_MIN_RADIUS`]; a parallel (a geographic grid's row) is a circle of radius
/// `N cos(lat)`, bending in the surface by `tan(lat) / N` as well, so its curvature is at most
/// `1 / (GEO_MIN_RADIUS cos(lat))`. Grids in projected coordinates bend less (their lines
/// are nearly geodesics); they take the same bound.
fn curve_radius(max_lat_deg: f64) -> f64 {
    let r = GEO_MIN_RADIUS as f64 * max_lat_deg.to_radians().cos();
    // Round down to an f32 so CPU and GPU grow boxes by the same radius.
    let f = r as f32;
    // (r > 0: the next f32 below is one bit pattern down.)
    let f = if f as f64 > r {
        f32::from_bits(f.to_bits() - 1)
    } else {
        f
    };
    f as f64
}

/// An axis-aligned box (metres): its lowest and highest corner.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldBox {
    pub lo: DVec3,
    pub hi: DVec3,
}

impl WorldBox {
    /// Is the box wholly outside one of `planes` (`(normal, offset)`, `dot(normal, p) +
    /// offset >= 0` inside, in the box's frame) by more than `slack` metres? The box corner
    /// farthest along each plane's normal decides (`box_outside` in
    /// `shaders/include/terrain_common.wgsl`).
    pub fn outside(&self, planes: &[[f32; 4]; 6], slack: f64) -> bool {
        planes.iter().any(|p| {
            let n = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            let v = DVec3::select(n.cmpge(DVec3::ZERO), self.hi, self.lo);
            n.dot(v) + (p[3] as f64) < -slack
        })
    }

    /// Does the box lie inside every one of `planes` by at least `margin` metres? The box
    /// corner nearest each plane's back side decides (`box_inside` in
    /// `shaders/include/terrain_common.wgsl`).
    pub fn inside(&self, planes: &[[f32; 4]; 6], margin: f64) -> bool {
        planes.iter().all(|p| {
            let n = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            let v = DVec3::select(n.cmpge(DVec3::ZERO), self.lo, self.hi);
            n.dot(v) + (p[3] as f64) >= margin
        })
    }

    /// The box moved by `-origin` (camera-relative boxes).
    pub fn relative_to(&self, origin: DVec3) -> WorldBox {
        WorldBox {
            lo: self.lo - origin,
            hi: self.hi - origin,
        }
    }
}

/// Culling on the earth: the lattice the terrain is drawn through and the camera's world
/// position (the frustum planes are camera-relative).
#[derive(Clone, Debug)]
pub struct EarthCull {
    pub lattice: Arc<Lattice>,
    pub camera: DVec3,
    /// 0 in the renderer. Tests comparing with the GPU's f32 decisions move the decision by
    /// this fraction of the box's distance from the camera (positive: culls more), bracketing
    /// the GPU's rounding (relative f32 errors of a few 1e-7).
    pub rounding: f64,
}

impl EarthCull {
    pub fn new(lattice: Arc<Lattice>, camera: DVec3) -> Self {
        EarthCull {
            lattice,
            camera,
            rounding: 0.0,
        }
    }

    /// Is the terrain over the grid rectangle `c0..=c1` between `heights` (metres) wholly
    /// outside one of the camera-relative `planes` by more than `slack` metres? The box is
    /// [`Lattice::rect_box`]; `earth_box` and `box_outside` in
    /// `shaders/include/terrain_common.wgsl` decide the same on the GPU.
    pub fn outside(
        &self,
        planes: &[[f32; 4]; 6],
        c0: [i32; 2],
        c1: [i32; 2],
        heights: [f32; 2],
        slack: f64,
    ) -> bool {
        let (b, shift) = self.relative_box(c0, c1, heights);
        b.outside(planes, slack - shift)
    }

    /// [`Self::outside`], and whether the same box lies inside every plane (`box_inside` on
    /// the GPU), from one box.
    pub fn visibility(
        &self,
        planes: &[[f32; 4]; 6],
        c0: [i32; 2],
        c1: [i32; 2],
        heights: [f32; 2],
        slack: f64,
    ) -> (bool, bool) {
        let (b, shift) = self.relative_box(c0, c1, heights);
        let outside = b.outside(planes, slack - shift);
        (outside, !outside && b.inside(planes, shift))
    }

    /// The camera-relative box over the rectangle, and how far [`Self::rounding`] moves the
    /// decision there (metres: that fraction of the box's distance from the camera).
    fn relative_box(&self, c0: [i32; 2], c1: [i32; 2], heights: [f32; 2]) -> (WorldBox, f64) {
        let b = self
            .lattice
            .rect_box(c0, c1, [heights[0] as f64, heights[1] as f64])
            .relative_to(self.camera);
        let far = b.lo.abs().max(b.hi.abs()).length();
        (b, self.rounding * far)
    }
}

/// Are `[sx, sy]` metres between samples square (to 1e-9)? A non-square grid (a geographic
/// one) is drawn natively on the ellipsoid and measured per axis ([`Lattice::lod_metric`]).
pub fn is_square([sx, sy]: [f64; 2]) -> bool {
    ((sx - sy) / sy).abs() <= 1e-9
}

impl Lattice {
    /// The default node step for a `width` x `height` grid whose samples are `spacing_m`
    /// apart (the larger metric spacing): lattice cells of at most [`CELL_M`] (the sagitta of
    /// their diagonal, the interpolation error, stays under 1 cm), coarser only where the
    /// lattice would exceed 1024 nodes per side (48 MB).
    pub fn step_for(width: u32, height: u32, spacing_m: f64) -> u32 {
        let by_metres = (CELL_M / spacing_m).floor().clamp(1.0, 65536.0) as u32;
        by_metres.max(width.max(height).div_ceil(1024))
    }

    /// Node counts per axis for `step`: the last node at or past the last sample.
    fn node_counts(width: u32, height: u32, step: u32) -> [u32; 2] {
        [
            (width.max(2) - 1).div_ceil(step) + 1,
            (height.max(2) - 1).div_ceil(step) + 1,
        ]
    }

    /// A lattice for a `width` x `height` grid in `frame`: `locate(col, row)` gives the
    /// geodetic latitude/longitude (degrees) of a sample position (it is asked for positions
    /// up to one step past the last sample).
    pub fn new(
        width: u32,
        height: u32,
        step: u32,
        frame: EnuFrame,
        mut locate: impl FnMut(f64, f64) -> Result<(f64, f64)>,
    ) -> Result<Self> {
        if step == 0 {
            return Err(Error::invalid("geolocation lattice", "step 0"));
        }
        let nodes = Self::node_counts(width, height, step);
        let count = nodes[0] as usize * nodes[1] as usize;
        let mut positions = Vec::with_capacity(count);
        let mut ups = Vec::with_capacity(count);
        let mut max_lat: f64 = 0.0;
        let mut lat_lon = Vec::with_capacity(count);
        for j in 0..nodes[1] {
            for i in 0..nodes[0] {
                let (lat, lon) = locate((i * step) as f64, (j * step) as f64)?;
                if !(lat.is_finite() && lon.is_finite() && lat.abs() <= 90.0) {
                    return Err(Error::invalid(
                        "geolocation lattice",
                        format!(
                            "sample ({}, {}) maps to latitude {lat}, longitude {lon}",
                            i * step,
                            j * step
                        ),
                    ));
                }
                max_lat = max_lat.max(lat.abs());
                positions.push(frame.to_local(WGS84.to_ecef(Geodetic::new(lat, lon, 0.0))));
                ups.push(frame.rotate_to_local(normal_ecef(lat, lon)));
                lat_lon.push([lat, lon]);
            }
        }
        Ok(Lattice {
            step,
            nodes,
            frame,
            positions,
            ups,
            curve_radius: curve_radius(max_lat),
            datum: vec![0.0; lat_lon.len()],
            lat_lon,
        })
    }

    /// The lattice on a vertical datum whose zero surface lies `height_above_ellipsoid(points)`
    /// metres above the ellipsoid at each node's latitude/longitude (`[lat, lon]` degrees, all
    /// nodes in one call so PROJ can transform them as one batch): every node moves along its
    /// ellipsoid normal to that surface; the up vectors stay the ellipsoid normals. For heights
    /// above the EGM96 geoid that is the undulation `N96` (`dataset::geoid`), so a sample of
    /// orthometric height `H` lies at ellipsoidal height `H + N` (`N` bilinear between nodes).
    pub fn on_datum(
        mut self,
        height_above_ellipsoid: impl FnOnce(&[[f64; 2]]) -> Result<Vec<f64>>,
    ) -> Result<Self> {
        let n = height_above_ellipsoid(&self.lat_lon)?;
        if n.len() != self.lat_lon.len() || n.iter().any(|v| !v.is_finite()) {
            return Err(Error::invalid(
                "geolocation lattice",
                format!(
                    "the vertical datum gave {} finite heights for {} nodes",
                    n.iter().filter(|v| v.is_finite()).count(),
                    self.lat_lon.len()
                ),
            ));
        }
        for ((p, [lat, lon]), h) in self.positions.iter_mut().zip(&self.lat_lon).zip(&n) {
            *p = self
                .frame
                .to_local(WGS84.to_ecef(Geodetic::new(*lat, *lon, *h)));
        }
        self.datum = n;
        Ok(self)
    }

    /// The vertical datum's height above the ellipsoid at each node (row-major; all 0 unless
    /// built [`Lattice::on_datum`]).
    pub fn datum_heights(&self) -> &[f64] {
        &self.datum
    }

    /// Node `(i, j)`'s geodetic latitude and longitude (degrees).
    pub fn node_lat_lon(&self, i: u32, j: u32) -> [f64; 2] {
        self.lat_lon[j as usize * self.nodes[0] as usize + i as usize]
    }

    /// A grid with `spacing` in metres and no georeferencing, anchored at `frame`'s origin:
    /// the world-plane point `(col * spacing, row * spacing, 0)` dropped onto the ellipsoid
    /// along the ellipsoid's normal (its geodetic latitude/longitude at height 0).
    pub fn anchored_plane(width: u32, height: u32, spacing: f64, frame: EnuFrame) -> Result<Self> {
        let step = Self::step_for(width, height, spacing);
        Self::new(width, height, step, frame, |c, r| {
            let g = WGS84.to_geodetic(frame.to_ecef(DVec3::new(c * spacing, r * spacing, 0.0)));
            Ok((g.lat_deg, g.lon_deg))
        })
    }

    /// A geographic grid: sample `(col, row)` at latitude `origin[1] + row * step_deg[1]`,
    /// longitude `origin[0] + col * step_deg[0]` (row 0 south), in the ENU frame at sample
    /// (0, 0) on the ellipsoid (the world frame of docs/coordinates.md).
    pub fn geographic(
        width: u32,
        height: u32,
        origin: [f64; 2],
        step_deg: [f64; 2],
    ) -> Result<Self> {
        let lon1 = origin[0] + (width - 1) as f64 * step_deg[0];
        let lat1 = origin[1] + (height - 1) as f64 * step_deg[1];
        if origin[0].min(lon1) < -180.0 || origin[0].max(lon1) > 180.0 {
            return Err(Error::invalid(
                "geographic grid",
                format!(
                    "longitudes {}..{lon1} cross the antimeridian, which is not supported",
                    origin[0]
                ),
            ));
        }
        if origin[1].min(lat1) <= -90.0 || origin[1].max(lat1) >= 90.0 {
            return Err(Error::invalid(
                "geographic grid",
                format!(
                    "latitudes {}..{lat1} reach a pole, which is not supported",
                    origin[1]
                ),
            ));
        }
        let frame = EnuFrame::new(&WGS84, Geodetic::new(origin[1], origin[0], 0.0));
        // The larger metric spacing: east-west at the equator-most row, or north-south.
        let equator_lat = if origin[1] * lat1 <= 0.0 {
            0.0
        } else {
            origin[1].abs().min(lat1.abs())
        };
        let ew = WGS84.prime_vertical_radius(equator_lat)
            * equator_lat.to_radians().cos()
            * step_deg[0].abs().to_radians();
        let ns = WGS84.meridian_radius(origin[1]) * step_deg[1].abs().to_radians();
        let step = Self::step_for(width, height, ew.max(ns));
        Self::new(width, height, step, frame, |c, r| {
            Ok((origin[1] + r * step_deg[1], origin[0] + c * step_deg[0]))
        })
    }

    /// The GPU layout: per node `[hi.xyz, 0, lo.xyz, 0, up.xyz, 0]`.
    pub fn gpu_nodes(&self) -> Vec<f32> {
        let mut out = Vec::with_capacity(self.positions.len() * NODE_FLOATS);
        for (p, u) in self.positions.iter().zip(&self.ups) {
            let (hi, lo) = split(*p);
            let u = u.as_vec3();
            out.extend_from_slice(&[hi[0], hi[1], hi[2], 0.0, lo[0], lo[1], lo[2], 0.0]);
            out.extend_from_slice(&[u.x, u.y, u.z, 0.0]);
        }
        out
    }

    /// Node `(i, j)`'s world position and up vector, as the GPU stores them (hi + lo, f32
    /// up) in f64.
    pub fn node_position(&self, i: i64, j: i64) -> (DVec3, DVec3) {
        let k = j as usize * self.nodes[0] as usize + i as usize;
        let (hi, lo) = split(self.positions[k]);
        let p = glam::Vec3::from(hi).as_dvec3() + glam::Vec3::from(lo).as_dvec3();
        (p, self.ups[k].as_vec3().as_dvec3())
    }

    /// World position (f64) of the surface point at sample position `s` (columns, rows) and
    /// `height` metres: the shader's formula on the shader's data (the CPU mirror).
    pub fn position(&self, s: DVec2, height: f64) -> DVec3 {
        let ([(p00, u00), (p10, u10), (p01, u01), (p11, u11)], f) = self.cell_nodes(s);
        let lerp = |a: DVec3, b: DVec3, t: f64| a * (1.0 - t) + b * t;
        let p = lerp(lerp(p00, p10, f.x), lerp(p01, p11, f.x), f.y);
        let u = lerp(lerp(u00, u10, f.x), lerp(u01, u11, f.x), f.y);
        p + u * height
    }

    /// The smallest metres per sample along the grid's columns (x) and rows (y) anywhere on
    /// the lattice, at `height` metres (the drawn surface's, as the GPU stores the nodes).
    /// Between nodes the lattice is bilinear, so along a node edge a sample step is a
    /// `1 / step` share of the edge's chord: the minimum over all node edges is the minimum
    /// over the grid. A geographic grid's east-west minimum lies on its poleward row, its
    /// north-south one on its equator-most row. UDLOD's per-axis LOD metric
    /// (`udlod::levels::Levels::on_lattice`).
    pub fn min_axis_spacing(&self, height: f64) -> [f64; 2] {
        let [ni, nj] = self.nodes.map(|n| n as i64);
        let at = |i: i64, j: i64| {
            let (p, u) = self.node_position(i, j);
            p + u * height
        };
        let mut min = [f64::INFINITY; 2];
        for j in 0..nj {
            for i in 0..ni {
                let p = at(i, j);
                if i + 1 < ni {
                    min[0] = min[0].min((at(i + 1, j) - p).length());
                }
                if j + 1 < nj {
                    min[1] = min[1].min((at(i, j + 1) - p).length());
                }
            }
        }
        min.map(|m| m / self.step as f64)
    }

    /// The (position, up) of the four nodes of the lattice cell holding sample position `s`
    /// (south-west, south-east, north-west, north-east) and the fraction of the cell
    /// ([`Lattice::cell_of`]).
    fn cell_nodes(&self, s: DVec2) -> ([(DVec3, DVec3); 4], DVec2) {
        let (i, j, f) = self.cell_of(s);
        let nodes =
            [(0, 0), (1, 0), (0, 1), (1, 1)].map(|(di, dj)| self.node_position(i + di, j + dj));
        (nodes, f)
    }

    /// The lattice cell holding sample position `s` (its south-west node, clamped to the
    /// lattice) and the fraction of the cell (outside the lattice: the edge cell's
    /// extrapolation).
    fn cell_of(&self, s: DVec2) -> (i64, i64, DVec2) {
        let step = self.step as f64;
        let last = [self.nodes[0] as i64 - 2, self.nodes[1] as i64 - 2];
        let i = ((s.x / step).floor() as i64).clamp(0, last[0]);
        let j = ((s.y / step).floor() as i64).clamp(0, last[1]);
        (i, j, (s - DVec2::new(i as f64, j as f64) * step) / step)
    }

    /// Metres per sample along columns and rows at sample position `s` and `height` on the
    /// drawn surface (the chords to `s + (1, 0)` and `s + (0, 1)`; outside the grid the
    /// lattice's extrapolation, where a geographic grid's east-west spacing keeps shrinking
    /// poleward). Chunked LOD's metric for a viewer beyond the grid's edge.
    pub fn axis_spacing_at(&self, s: DVec2, height: f64) -> [f64; 2] {
        let p = self.position(s, height);
        [
            (self.position(s + DVec2::X, height) - p).length(),
            (self.position(s + DVec2::Y, height) - p).length(),
        ]
    }

    /// A per-axis LOD stretch (`stretch`: each axis's metric spacing over the grid frame's
    /// `spacing`) lowered to the drawn surface's spacing at the LOD viewer's sample position
    /// `viewer` (at `lowest`, the data's lowest height, or the datum if higher) where that is
    /// smaller. A viewer beyond a geographic grid's poleward edge stands where the
    /// extrapolated east-west spacing is below the grid's smallest (1.8 % at 66 km past the
    /// edge of a 60 N grid), and distances measured from there with the grid's would exceed
    /// the true ones. Each axis's spacing changes monotonically with latitude, so the smaller
    /// of the two ends bounds it along the way. A square grid's `[1, 1]` is kept as it is.
    /// UDLOD's, chunked LOD's and GeoMipMapping's per-frame metric.
    pub fn stretch_at(
        &self,
        stretch: [f64; 2],
        spacing: f64,
        viewer: DVec2,
        lowest: f64,
    ) -> [f64; 2] {
        if stretch == [1.0, 1.0] {
            return stretch;
        }
        let here = self.axis_spacing_at(viewer, lowest.min(0.0));
        [0, 1].map(|k| stretch[k].min(here[k] / spacing))
    }

    /// The LOD metric of a grid drawn through this lattice whose stated metres between
    /// samples are `axis_spacing` and whose lowest height is `lowest` (m): on a native
    /// non-square grid (a geographic one) each axis's smallest spacing on the drawn surface at
    /// the lowest height where that lies below the datum ([`Lattice::min_axis_spacing`]); None
    /// on a square grid, whose one spacing stays the metric. UDLOD's
    /// (`udlod::levels::Levels::on_lattice`) and GeoMipMapping's distances.
    pub fn lod_metric(&self, axis_spacing: [f64; 2], lowest: f64) -> Option<[f64; 2]> {
        if is_square(axis_spacing) {
            return None;
        }
        Some(self.min_axis_spacing(lowest.min(0.0)))
    }

    /// The radius [`Lattice::rect_box`] grows boxes by the sagitta over (metres; an f32
    /// value, uploaded as `frame.lattice.w`).
    pub fn curve_radius(&self) -> f64 {
        self.curve_radius
    }

    /// The world box around the terrain over the grid rectangle from sample `c0` to sample
    /// `c1` (inclusive corners, `c0 <= c1`) between heights `heights[0]..heights[1]` on the
    /// earth: the box around the rectangle's four corners at both heights through the lattice
    /// ([`Lattice::position`]), grown on every axis by the sagitta of its horizontal diagonal
    /// `d`, `d^2 / (8 R)` with `R` = [`Lattice::curve_radius`] (between its corners the curved
    /// surface and the grid's lines bulge at most that far out of their hull), plus `1e-3 d`
    /// (the lattice's 1 cm interpolation error, the up vector's tilt times the height, and f32
    /// rounding on the GPU). Every method culls on the earth with this box: UDLOD and chunked
    /// LOD on the GPU through its WGSL twin `earth_box` (`shaders/include/terrain_common.wgsl`)
    /// and in their CPU references, GeoMipMapping on the CPU (docs/coordinates.md, "Culling
    /// with curvature").
    pub fn rect_box(&self, c0: [i32; 2], c1: [i32; 2], heights: [f64; 2]) -> WorldBox {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for k in 0..8 {
            let c = DVec2::new(
                if k & 1 != 0 { c1[0] } else { c0[0] } as f64,
                if k & 2 != 0 { c1[1] } else { c0[1] } as f64,
            );
            let p = self.position(c, heights[(k >= 4) as usize]);
            lo = lo.min(p);
            hi = hi.max(p);
        }
        let d = (hi.truncate() - lo.truncate()).length();
        let bulge = DVec3::splat(d * d / (8.0 * self.curve_radius) + 1e-3 * d);
        WorldBox {
            lo: lo - bulge,
            hi: hi + bulge,
        }
    }

    /// Where world point `p` lies over the lattice: the sample position `s` whose surface
    /// normal line passes through `p`, and `p`'s height above the lattice surface along it
    /// (`position(s, height) == p`): a height in the data set's vertical datum, as the
    /// terrain's heights are (the lattice surface is the datum's zero, [`Lattice::on_datum`]).
    /// Gauss-Newton on the CPU mirror: the mapping is smooth and nearly linear, so a few
    /// iterations reach 1e-9 samples; points outside the grid extrapolate from the edge
    /// cells. The renderer measures LOD distances from this point.
    pub fn sample_at(&self, p: DVec3) -> (DVec2, f64) {
        let mut s = DVec2::new(
            (self.nodes[0] - 1) as f64 * self.step as f64 / 2.0,
            (self.nodes[1] - 1) as f64 * self.step as f64 / 2.0,
        );
        let mut height = 0.0;
        for _ in 0..50 {
            let base = self.position(s, 0.0);
            // The interpolated up vector as `position` applies it (not renormalized).
            let up = self.position(s, 1.0) - base;
            let r = p - base;
            height = r.dot(up) / up.length_squared();
            let e = r - up * height;
            let dx = self.position(s + DVec2::X, 0.0) - base;
            let dy = self.position(s + DVec2::Y, 0.0) - base;
            // Least squares: [dx dy] ds = e.
            let (a, b, c) = (dx.dot(dx), dx.dot(dy), dy.dot(dy));
            let det = a * c - b * b;
            if det.abs() < 1e-30 {
                break;
            }
            let (ex, ey) = (dx.dot(e), dy.dot(e));
            let ds = DVec2::new(c * ex - b * ey, a * ey - b * ex) / det;
            s += ds;
            if ds.length() < 1e-9 {
                break;
            }
        }
        (s, height)
    }

    /// The largest distance between the interpolated surface of a lattice on the ellipsoid
    /// (not [`Lattice::on_datum`]) and the true ellipsoid surface over `locate`'s points, measured at every sample of a `probe_step` grid (tests
    /// and docs: the interpolation part of the error budget).
    pub fn max_interpolation_error(
        &self,
        width: u32,
        height: u32,
        probe_step: u32,
        mut locate: impl FnMut(f64, f64) -> Result<(f64, f64)>,
    ) -> Result<f64> {
        let mut worst: f64 = 0.0;
        for r in (0..height).step_by(probe_step.max(1) as usize) {
            for c in (0..width).step_by(probe_step.max(1) as usize) {
                let (lat, lon) = locate(c as f64, r as f64)?;
                let exact = self
                    .frame
                    .to_local(WGS84.to_ecef(Geodetic::new(lat, lon, 0.0)));
                let got = self.position(DVec2::new(c as f64, r as f64), 0.0);
                worst = worst.max((got - exact).length());
            }
        }
        Ok(worst)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nodes_are_exact_and_cells_stay_within_the_sagitta() {
        // 1025 x 1025 samples of 30 m at 46 N: nodes every 16 samples (480 m).
        let frame = EnuFrame::new(&WGS84, Geodetic::new(46.0, 8.0, 0.0));
        let l = Lattice::anchored_plane(1025, 1025, 30.0, frame).unwrap();
        assert_eq!((l.step, l.nodes), (16, [65, 65]));
        let locate = |c: f64, r: f64| -> Result<(f64, f64)> {
            let g = WGS84.to_geodetic(frame.to_ecef(DVec3::new(c * 30.0, r * 30.0, 0.0)));
            Ok((g.lat_deg, g.lon_deg))
        };
        // At nodes: exact to the split-double rounding.
        let at_nodes = l.max_interpolation_error(1025, 1025, 16, locate).unwrap();
        assert!(at_nodes < 1e-6, "{at_nodes}");
        // Between nodes: bounded by the sagitta of the cell diagonal, d^2 / (8 R).
        let between = l.max_interpolation_error(1025, 1025, 7, locate).unwrap();
        let d = 480.0 * 2f64.sqrt();
        let bound = d * d / (8.0 * 6.3e6);
        assert!(between > 1e-4 && between < bound, "{between} vs {bound}");
        // Up is the world z at the origin and tilts away from it far off.
        let u = l.position(DVec2::ZERO, 1.0) - l.position(DVec2::ZERO, 0.0);
        assert!((u - DVec3::Z).length() < 1e-7, "{u}");
        // 30 km north: about 70 m below the tangent plane.
        let p = l.position(DVec2::new(0.0, 1000.0), 0.0);
        assert!((p.z + 70.6).abs() < 1.0, "{p}");
    }

    #[test]
    fn sample_at_inverts_position() {
        let frame = EnuFrame::new(&WGS84, Geodetic::new(60.0, 20.0, 0.0));
        let l = Lattice::geographic(1201, 801, [20.0, 60.0], [1.0 / 1200.0, 1.0 / 1200.0]).unwrap();
        assert_eq!(l.frame.origin, frame.origin);
        for (s, h) in [
            (DVec2::new(0.0, 0.0), 0.0),
            (DVec2::new(1000.3, 700.9), 2500.0),
            (DVec2::new(37.25, 555.5), -30.0),
            // Outside the grid (a viewer beyond its edge).
            (DVec2::new(-150.0, 900.0), 9000.0),
        ] {
            let p = l.position(s, h);
            let (got, got_h) = l.sample_at(p);
            assert!((got - s).length() < 1e-6, "{s} -> {got}");
            assert!((got_h - h).abs() < 1e-6, "{h} -> {got_h}");
        }
    }

    #[test]
    fn on_datum_lifts_every_node_along_its_normal() {
        let (w, h, d) = (601u32, 401u32, 1.0 / 1200.0);
        let flat = Lattice::geographic(w, h, [7.5, 46.0], [d, d]).unwrap();
        // A smooth made-up undulation (metres) with a slope like the geoid's in mountains.
        let n = |lat: f64, lon: f64| 48.0 + 3.0 * (lat - 46.0) - 2.0 * (lon - 7.5);
        let lifted = flat
            .clone()
            .on_datum(|pts| Ok(pts.iter().map(|[la, lo]| n(*la, *lo)).collect()))
            .unwrap();
        assert_eq!((lifted.step, lifted.nodes), (flat.step, flat.nodes));
        // A sample of height 1000 in the datum lies at ellipsoidal height 1000 + N: within the
        // sagitta bound of the lattice on the ellipsoid (1 cm for these 460 m cells; N is
        // linear here, so its interpolation adds nothing measurable).
        for (c, r) in [(0.0, 0.0), (300.0, 200.0), (123.0, 77.0), (600.0, 400.0)] {
            let (lat, lon) = (46.0 + r * d, 7.5 + c * d);
            let want =
                lifted
                    .frame
                    .to_local(WGS84.to_ecef(Geodetic::new(lat, lon, 1000.0 + n(lat, lon))));
            let got = lifted.position(DVec2::new(c, r), 1000.0);
            assert!((got - want).length() < 1e-2, "({c}, {r}): {got} vs {want}");
            // Negative control: the lattice on the ellipsoid misses by N.
            let miss = (flat.position(DVec2::new(c, r), 1000.0) - want).length();
            assert!((miss - n(lat, lon)).abs() < 1e-2, "{miss}");
            // The inverse gives the height in the datum, not above the ellipsoid.
            let (s, back) = lifted.sample_at(got);
            assert!((s - DVec2::new(c, r)).length() < 1e-6 && (back - 1000.0).abs() < 1e-6);
        }
        assert_eq!(
            lifted.node_lat_lon(1, 0),
            [46.0, 7.5 + lifted.step as f64 * d]
        );
        let spread = lifted
            .datum_heights()
            .iter()
            .copied()
            .fold(f64::MIN, f64::max)
            - lifted
                .datum_heights()
                .iter()
                .copied()
                .fold(f64::MAX, f64::min);
        assert!(spread > 1.0 && flat.datum_heights().iter().all(|v| *v == 0.0));
        // A datum that answers for fewer nodes, or NaN, is a one-line error.
        let e = flat
            .clone()
            .on_datum(|_| Ok(vec![1.0]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("nodes") && !e.contains('\n'), "{e}");
        let e = flat
            .on_datum(|p| Ok(vec![f64::NAN; p.len()]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("finite"), "{e}");
    }

    #[test]
    fn antimeridian_and_poles_are_one_line_errors() {
        let e = Lattice::geographic(101, 11, [179.95, 10.0], [0.001, 0.001]).unwrap_err();
        assert!(e.to_string().contains("antimeridian"), "{e}");
        let e = Lattice::geographic(11, 101, [10.0, 89.95], [0.001, 0.001]).unwrap_err();
        assert!(e.to_string().contains("pole"), "{e}");
        assert!(Lattice::geographic(11, 11, [179.98, 89.98], [0.001, 0.001]).is_ok());
    }

    #[test]
    fn step_keeps_the_lattice_small() {
        assert_eq!(Lattice::step_for(1201, 1201, 30.0), 16);
        assert_eq!(Lattice::step_for(1201, 1201, 90.0), 5);
        assert_eq!(Lattice::step_for(16384, 16384, 30.0), 16);
        assert_eq!(Lattice::step_for(16384, 16384, 2.0), 250);
        assert_eq!(Lattice::step_for(600, 600, 1000.0), 1);
        assert_eq!(Lattice::node_counts(1201, 1201, 16), [76, 76]);
        assert_eq!(Lattice::node_counts(17, 2, 16), [2, 2]);
    }
}
