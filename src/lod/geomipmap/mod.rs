//! GeoMipMapping with border permutations (de Boer's GeoMipMaps as Tabakovic's ATLOD uses
//! them): the data is cut into blocks of 2^n + 1 samples ([`BLOCK_QUADS`] + 1, n = 5); each
//! block is drawn at one level (every 2^level-th sample) chosen on the CPU from the 3D distance
//! between the viewer and the block's bounding box; neighbours differ by at most one level,
//! and a block whose neighbour is coarser drops its odd border vertices on that side (one of
//! 16 border permutations), so the shared edge is the coarse one and no crack opens. One index
//! buffer holds every (level, permutation) list; the vertex stage (`shaders/geomipmap.wgsl`)
//! turns (block, sample) into a position through the shared helpers. No morphing: a level
//! change moves vertices at once (the popping metric shows it).

pub mod settings;

use std::sync::Arc;

use ash::vk;
use glam::DVec3;

use super::blocks::BlockBounds;
use super::udlod::params::frustum_planes;
use super::{LodMethod, MethodContext};
use crate::driver::Gpu;
use crate::driver::memory::Buffer;
use crate::driver::pipeline::{Pipeline, TerrainPipelineDesc, terrain_pipeline};
use crate::error::Result;
use crate::frame::ViewState;
use crate::geo::EarthCull;
pub use crate::gpu_constants::GEOMIPMAP_BLOCK_QUADS as BLOCK_QUADS;
use crate::slots::ViewSlot;
use settings::{CullBox, GeomipmapSettings};

/// Levels 0 (every sample) to 5 (the block's four corners).
pub const LEVELS: u32 = BLOCK_QUADS.trailing_zeros() + 1;

/// Border sides, as bits of a permutation: the neighbour on that side is one level coarser.
pub const WEST: u32 = 1;
pub const EAST: u32 = 2;
pub const SOUTH: u32 = 4;
pub const NORTH: u32 = 8;

/// Counter-clockwise triangles of a block at `level` whose `coarser` sides (bits above) meet a
/// neighbour one level coarser: the grid of every 2^level-th sample, with each odd border
/// vertex of a coarser side moved onto the even vertex before it (the triangles touching it
/// then fan from the coarse edge; the degenerate ones are left out). Indices address the
/// block's full (BLOCK_QUADS + 1)² sample grid.
pub fn block_indices(level: u32, coarser: u32) -> Vec<u16> {
    let step = 1u32 << level;
    let quads = BLOCK_QUADS / step;
    // The coarsest level (one quad) has no coarser neighbour: its 16 lists are the same.
    let coarser = if quads >= 2 { coarser } else { 0 };
    let row = BLOCK_QUADS + 1;
    let at = |x: u32, y: u32| -> u16 {
        // Positions in units of `step`; a coarser side snaps its odd positions down.
        let (mut x, mut y) = (x, y);
        let stitch = |side: u32, on: bool, k: &mut u32| {
            if coarser & side != 0 && on && *k % 2 == 1 {
                *k -= 1;
            }
        };
        let (x0, y0) = (x, y);
        stitch(WEST, x0 == 0, &mut y);
        stitch(EAST, x0 == quads, &mut y);
        stitch(SOUTH, y0 == 0, &mut x);
        stitch(NORTH, y0 == quads, &mut x);
        (y * step * row + x * step) as u16
    };
    let mut out = Vec::with_capacity((quads * quads * 6) as usize);
    for r in 0..quads {
        for c in 0..quads {
            let (a, b, cc, d) = (at(c, r), at(c + 1, r), at(c, r + 1), at(c + 1, r + 1));
            for t in [[a, b, cc], [b, d, cc]] {
                // Collapsed triangles (two corners on one vertex, or all three on one line
                // where two stitched sides meet) cover nothing.
                if signed_area2(t) != 0 {
                    out.extend(t);
                }
            }
        }
    }
    out
}

/// Twice the signed area of a triangle of block-grid indices (in samples²).
fn signed_area2(t: [u16; 3]) -> i64 {
    let row = (BLOCK_QUADS + 1) as i64;
    let p = |i: u16| ((i as i64) % row, (i as i64) / row);
    let (a, b, c) = (p(t[0]), p(t[1]), p(t[2]));
    (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0)
}

/// Per-block levels for a viewer (grid frame: `x = col * spacing`, `y = row * spacing`):
/// level 0 within `factor` block widths (`BLOCK_QUADS * spacing`) of the block's box, one more
/// per doubling of the distance, at most `LEVELS - 1`; then lowered until neighbours differ by
/// at most one level. Distances are measured with the grid frame's x and y offsets times
/// `stretch` (`[1, 1]` except on a native non-square grid on the earth, where each axis is
/// measured with its own smallest metric spacing: [`Lattice::lod_metric`]).
///
/// [`Lattice::lod_metric`]: crate::geo::Lattice::lod_metric
pub fn select_levels(
    bounds: &BlockBounds,
    spacing: f64,
    stretch: [f64; 2],
    viewer: DVec3,
    factor: f64,
) -> Vec<u32> {
    let width = BLOCK_QUADS as f64 * spacing;
    let (cols, rows) = (bounds.cols, bounds.rows);
    let mut levels = Vec::with_capacity((cols * rows) as usize);
    for j in 0..rows {
        for i in 0..cols {
            let d = block_distance(bounds, spacing, stretch, viewer, i, j);
            let ratio = d / (factor * width);
            let level = if ratio < 1.0 {
                0
            } else {
                (ratio.log2().floor() as u32 + 1).min(LEVELS - 1)
            };
            levels.push(level);
        }
    }
    // Lower a block's level while a neighbour is more than one level finer.
    let mut changed = true;
    while changed {
        changed = false;
        for j in 0..rows {
            for i in 0..cols {
                let k = (j * cols + i) as usize;
                let mut l = levels[k];
                for (di, dj) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                    let (ni, nj) = (i as i64 + di, j as i64 + dj);
                    if ni >= 0 && nj >= 0 && ni < cols as i64 && nj < rows as i64 {
                        l = l.min(levels[(nj as u32 * cols + ni as u32) as usize] + 1);
                    }
                }
                if l != levels[k] {
                    levels[k] = l;
                    changed = true;
                }
            }
        }
    }
    levels
}

/// The border permutation of block `(i, j)`: the sides whose neighbour is coarser.
pub fn border_mask(levels: &[u32], cols: u32, rows: u32, i: u32, j: u32) -> u32 {
    let l = levels[(j * cols + i) as usize];
    let coarser = |ni: u32, nj: u32| levels[(nj * cols + ni) as usize] > l;
    let mut mask = 0;
    if i > 0 && coarser(i - 1, j) {
        mask |= WEST;
    }
    if i + 1 < cols && coarser(i + 1, j) {
        mask |= EAST;
    }
    if j > 0 && coarser(i, j - 1) {
        mask |= SOUTH;
    }
    if j + 1 < rows && coarser(i, j + 1) {
        mask |= NORTH;
    }
    mask
}

/// One list of the shared index buffer.
#[derive(Clone, Copy, Debug)]
struct List {
    first: u32,
    count: u32,
}

/// Distance from `viewer` (grid-frame metres and height) to block `(i, j)`'s box (its
/// rectangle x its min/max height), each horizontal axis stretched by `stretch`: the distance
/// [`select_levels`] chooses levels by.
pub fn block_distance(
    bounds: &BlockBounds,
    spacing: f64,
    stretch: [f64; 2],
    viewer: DVec3,
    i: u32,
    j: u32,
) -> f64 {
    let width = BLOCK_QUADS as f64 * spacing;
    let s = DVec3::new(stretch[0], stretch[1], 1.0);
    let [lo, hi] = bounds.get(i, j);
    let lo_xy = DVec3::new(i as f64 * width, j as f64 * width, lo as f64) * s;
    let hi_xy = DVec3::new((i + 1) as f64 * width, (j + 1) as f64 * width, hi as f64) * s;
    let viewer = viewer * s;
    viewer.clamp(lo_xy, hi_xy).distance(viewer)
}

/// A frame's LOD stretch: `stretch` (the grid's, `lod_stretch`) lowered on the earth to the
/// spacing at the LOD viewer where that is smaller ([`Lattice::stretch_at`]: a viewer beyond a
/// geographic grid's poleward edge). `lowest`: the data's lowest height.
///
/// [`Lattice::stretch_at`]: crate::geo::Lattice::stretch_at
pub fn frame_stretch(
    lattice: Option<&crate::geo::Lattice>,
    stretch: [f64; 2],
    spacing: f64,
    lowest: f64,
    lod_viewer: DVec3,
) -> [f64; 2] {
    lattice.map_or(stretch, |l| {
        let viewer = glam::DVec2::new(lod_viewer.x, lod_viewer.y) / spacing;
        l.stretch_at(stretch, spacing, viewer, lowest)
    })
}

/// A block's draw: its list and its index (the instance index the vertex stage reads).
#[derive(Clone, Copy, Debug)]
struct Draw {
    list: List,
    block: u32,
}

/// The grid frame's stretch per axis for the LOD distances ([`select_levels`]): on the earth
/// the lattice's per-axis metric over the grid frame's spacing, else `[1, 1]`.
fn lod_stretch(ctx: &MethodContext<'_>) -> [f64; 2] {
    let info = &ctx.terrain.info;
    ctx.lattice
        .and_then(|l| l.lod_metric(ctx.data.axis_spacing(), info.min_height as f64))
        .map_or([1.0, 1.0], |m| m.map(|m| m / info.spacing))
}

pub struct Geomipmap {
    gpu: Arc<Gpu>,
    settings: GeomipmapSettings,
    pipeline: Pipeline,
    indices: Buffer,
    /// `lists[level * 16 + permutation]`.
    lists: Vec<List>,
    bounds: BlockBounds,
    spacing: f64,
    /// The LOD metric's stretch of the grid frame per axis (see [`select_levels`]).
    stretch: [f64; 2],
    /// The data's lowest height (m): where the per-frame stretch takes the spacing.
    lowest: f64,
    /// The data's last sample per axis (blocks past it are clamped to it).
    last: [i32; 2],
    /// The geolocation lattice (None: the flat world, or the grid-frame box asked for): blocks
    /// are culled with its curved boxes.
    lattice: Option<Arc<crate::geo::Lattice>>,
    draws: Vec<Vec<Draw>>,
    triangles: Vec<u64>,
}

impl Geomipmap {
    pub fn new(ctx: &MethodContext<'_>, settings: &GeomipmapSettings) -> Result<Self> {
        settings.validate()?;
        let gpu = ctx.gpu;
        let bounds = BlockBounds::new(ctx.data, BLOCK_QUADS)?;
        let mut all: Vec<u16> = Vec::new();
        let mut lists = Vec::new();
        for level in 0..LEVELS {
            for mask in 0..16 {
                let l = block_indices(level, mask);
                lists.push(List {
                    first: all.len() as u32,
                    count: l.len() as u32,
                });
                all.extend(l);
            }
        }
        let bytes: &[u8] = bytemuck::cast_slice(&all);
        let indices = Buffer::with_data(
            gpu,
            "geomipmap indices",
            vk::BufferUsageFlags::INDEX_BUFFER,
            bytes,
        )?;
        let pipeline = terrain_pipeline(
            gpu,
            &ctx.formats,
            &TerrainPipelineDesc::triangles(
                crate::driver::shaders::GEOMIPMAP_SPV.variant(ctx.terrain.variant),
                &[ctx.terrain.descriptors.layout],
            ),
        )?;
        Ok(Geomipmap {
            gpu: gpu.clone(),
            settings: settings.clone(),
            pipeline,
            indices,
            lists,
            bounds,
            spacing: ctx.terrain.info.spacing,
            stretch: lod_stretch(ctx),
            lowest: ctx.terrain.info.min_height as f64,
            last: [
                ctx.terrain.info.width as i32 - 1,
                ctx.terrain.info.height as i32 - 1,
            ],
            lattice: ctx
                .lattice
                .filter(|_| settings.cull_box == CullBox::Lattice)
                .cloned(),
            draws: vec![Vec::new(); ctx.slots],
            triangles: vec![0; ctx.slots],
        })
    }

    /// Whether block `(i, j)`'s box lies wholly outside one frustum plane. On the earth the
    /// box is the curved one every method culls with there ([`EarthCull::outside`], with
    /// UDLOD's margin of 1e-3 of the block's side); on the flat world the grid-frame box.
    fn culled(
        &self,
        planes: &[[f32; 4]; 6],
        earth: Option<&EarthCull>,
        eye: DVec3,
        i: u32,
        j: u32,
    ) -> bool {
        let width = BLOCK_QUADS as f64 * self.spacing;
        if let Some(earth) = earth {
            let q = BLOCK_QUADS as i32;
            let c0 = [i as i32 * q, j as i32 * q];
            let c1 = [(c0[0] + q).min(self.last[0]), (c0[1] + q).min(self.last[1])];
            return earth.outside(planes, c0, c1, self.bounds.get(i, j), 1e-3 * width);
        }
        let [lo, hi] = self.bounds.get(i, j);
        let lo = DVec3::new(i as f64 * width, j as f64 * width, lo as f64) - eye;
        let hi = DVec3::new((i + 1) as f64 * width, (j + 1) as f64 * width, hi as f64) - eye;
        planes.iter().any(|p| {
            let n = DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            // The box corner farthest along the normal.
            let v = DVec3::new(
                if n.x >= 0.0 { hi.x } else { lo.x },
                if n.y >= 0.0 { hi.y } else { lo.y },
                if n.z >= 0.0 { hi.z } else { lo.z },
            );
            n.dot(v) + (p[3] as f64) < 0.0
        })
    }
}

impl LodMethod for Geomipmap {
    fn name(&self) -> &'static str {
        "geomipmap"
    }

    fn update(&mut self, slot: ViewSlot, view: &ViewState) -> Result<()> {
        let stretch = frame_stretch(
            self.lattice.as_deref(),
            self.stretch,
            self.spacing,
            self.lowest,
            view.lod_viewer,
        );
        let levels = select_levels(
            &self.bounds,
            self.spacing,
            stretch,
            view.lod_viewer,
            self.settings.distance_factor,
        );
        let planes = frustum_planes(&view.camera, view.width as f64 / view.height as f64);
        let earth = self
            .lattice
            .as_ref()
            .map(|l| EarthCull::new(l.clone(), view.camera.position));
        let (cols, rows) = (self.bounds.cols, self.bounds.rows);
        let mut draws = std::mem::take(&mut self.draws[slot.index()]);
        draws.clear();
        let mut triangles = 0u64;
        for j in 0..rows {
            for i in 0..cols {
                if self.settings.cull
                    && self.culled(&planes, earth.as_ref(), view.camera.position, i, j)
                {
                    continue;
                }
                let block = j * cols + i;
                let mask = if self.settings.stitch {
                    border_mask(&levels, cols, rows, i, j)
                } else {
                    0
                };
                let list = self.lists[(levels[block as usize] * 16 + mask) as usize];
                triangles += list.count as u64 / 3;
                draws.push(Draw { list, block });
            }
        }
        self.draws[slot.index()] = draws;
        self.triangles[slot.index()] = triangles;
        Ok(())
    }

    fn record_draw(
        &mut self,
        cmd: vk::CommandBuffer,
        slot: ViewSlot,
        frame_set: vk::DescriptorSet,
    ) {
        let d = &self.gpu.device;
        unsafe {
            self.pipeline
                .bind(cmd, vk::PipelineBindPoint::GRAPHICS, &[frame_set]);
            d.cmd_bind_index_buffer(cmd, self.indices.raw, 0, vk::IndexType::UINT16);
            for draw in &self.draws[slot.index()] {
                d.cmd_draw_indexed(cmd, draw.list.count, 1, draw.list.first, 0, draw.block);
            }
        }
    }

    fn triangles(&self, slot: ViewSlot) -> u64 {
        self.triangles[slot.index()]
    }

    fn counters(&self, slot: ViewSlot) -> Vec<(&'static str, u64)> {
        vec![("blocks_drawn", self.draws[slot.index()].len() as u64)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn area2(t: &[u16]) -> i64 {
        signed_area2([t[0], t[1], t[2]])
    }

    #[test]
    fn every_permutation_covers_the_block_once_counter_clockwise() {
        let full = 2 * (BLOCK_QUADS as i64).pow(2);
        for level in 0..LEVELS {
            for mask in 0..16 {
                let l = block_indices(level, mask);
                let areas: Vec<i64> = l.chunks(3).map(area2).collect();
                assert!(areas.iter().all(|&a| a > 0), "level {level} mask {mask}");
                assert_eq!(areas.iter().sum::<i64>(), full, "level {level} mask {mask}");
            }
        }
    }

    /// The vertices on a block's side, in order along it.
    fn side_vertices(l: &[u16], side: u32) -> Vec<u16> {
        let row = BLOCK_QUADS + 1;
        let on = |i: u16| {
            let (x, y) = (i as u32 % row, i as u32 / row);
            match side {
                WEST => x == 0,
                EAST => x == BLOCK_QUADS,
                SOUTH => y == 0,
                _ => y == BLOCK_QUADS,
            }
        };
        let mut v: Vec<u16> = l.iter().copied().filter(|&i| on(i)).collect();
        v.sort_unstable();
        v.dedup();
        v
    }

    #[test]
    fn a_stitched_side_has_exactly_the_coarser_neighbours_vertices() {
        for level in 0..LEVELS - 1 {
            for side in [WEST, EAST, SOUTH, NORTH] {
                let fine = block_indices(level, side);
                let coarse = block_indices(level + 1, 0);
                assert_eq!(
                    side_vertices(&fine, side),
                    side_vertices(&coarse, side),
                    "level {level} side {side}"
                );
                // Control: without the permutation the side keeps the fine vertices.
                assert_ne!(
                    side_vertices(&block_indices(level, 0), side),
                    side_vertices(&coarse, side)
                );
            }
        }
    }

    /// A native geographic grid at 60 N, 257 x 257 samples of 3": its lattice, the metres per
    /// sample north-south (at 60 N) and east-west (at the poleward row, the grid frame's
    /// spacing), the per-axis stretch, procedural heights at that spacing and their blocks.
    struct Geographic60N {
        lattice: crate::geo::Lattice,
        ns: f64,
        ew: f64,
        stretch: [f64; 2],
        data: crate::dataset::Heightmap,
        bounds: BlockBounds,
    }

    fn geographic_60n() -> Geographic60N {
        let step = 1.0 / 1200.0;
        let lattice = crate::geo::Lattice::geographic(257, 257, [8.0, 60.0], [step, step]).unwrap();
        let top = 60.0 + 256.0 * step;
        let ns = crate::geo::WGS84.meridian_radius(60.0) * f64::to_radians(step);
        let ew = crate::geo::WGS84.prime_vertical_radius(top)
            * top.to_radians().cos()
            * step.to_radians();
        let metric = lattice.lod_metric([ew, ns], 0.0).expect("non-square");
        let stretch = metric.map(|m| m / ew);
        let data =
            crate::dataset::procedural::generate(&crate::dataset::procedural::ProceduralParams {
                size: 257,
                spacing: ew,
                ..Default::default()
            })
            .unwrap();
        let bounds = BlockBounds::new(&data, BLOCK_QUADS).unwrap();
        Geographic60N {
            lattice,
            ns,
            ew,
            stretch,
            data,
            bounds,
        }
    }

    /// From a viewer beyond the 60 N grid's poleward edge (66 km north of it and 40 km east,
    /// 3 km up: its distances run partly east-west, where the spacing shrinks poleward) every
    /// block's distance in the frame's stretch ([`frame_stretch`]) is at most the true one:
    /// the nearest chord from the viewer to the block's samples through the lattice. Control:
    /// the grid's stretch, not lowered at the viewer, is longer for some block.
    #[test]
    fn block_distances_are_lower_bounds_from_beyond_the_poleward_edge() {
        let Geographic60N {
            lattice,
            ns,
            ew,
            stretch,
            data,
            bounds,
        } = geographic_60n();
        let lowest = data.height_range().0 as f64;
        let (col, row) = (256.0 + 40e3 / ew, 256.0 + 66e3 / ns);
        let viewer = DVec3::new(col * ew, row * ew, 3000.0);
        let at_viewer = lattice.position(glam::DVec2::new(col, row), viewer.z);
        let lowered = frame_stretch(Some(&lattice), stretch, ew, lowest, viewer);
        assert!(lowered[0] < stretch[0], "{lowered:?} vs {stretch:?}");
        let (mut worst, mut worst_grid) = (0.0f64, 0.0f64);
        for j in 0..bounds.rows {
            for i in 0..bounds.cols {
                let mut nearest = f64::INFINITY;
                let q = BLOCK_QUADS;
                for r in (j * q..=(j + 1) * q).step_by(4) {
                    for c in (i * q..=(i + 1) * q).step_by(4) {
                        let s = glam::DVec2::new(c as f64, r as f64);
                        let p = lattice.position(s, data.sample(c, r) as f64);
                        nearest = nearest.min((p - at_viewer).length());
                    }
                }
                let d = |stretch| block_distance(&bounds, ew, stretch, viewer, i, j) / nearest;
                worst = worst.max(d(lowered));
                worst_grid = worst_grid.max(d(stretch));
            }
        }
        println!(
            "block distance / true: {worst} (grid stretch {worst_grid}), stretch {lowered:?} vs {stretch:?}"
        );
        assert!(worst <= 1.0, "block distance exceeds the true one: {worst}");
        assert!(worst_grid > 1.0, "control: {worst_grid}");
        // The flat world (no lattice) keeps the grid's stretch.
        assert_eq!(frame_stretch(None, stretch, ew, lowest, viewer), stretch);
    }

    /// On a native geographic grid at 60 N (north-south samples twice as far apart as
    /// east-west) the per-axis metric measures north-south distances with their own spacing:
    /// no block is finer than with the one smallest spacing on both axes, and blocks north and
    /// south of the viewer are coarser. Control: a square grid has no per-axis metric.
    #[test]
    fn geographic_grids_measure_each_axis_with_its_own_spacing() {
        let Geographic60N {
            lattice,
            ns,
            ew,
            stretch,
            bounds,
            ..
        } = geographic_60n();
        assert!((stretch[0] - 1.0).abs() < 1e-3, "{stretch:?}");
        assert!((stretch[1] - ns / ew).abs() < 1e-3 * ns / ew, "{stretch:?}");
        assert!(lattice.lod_metric([ew, ew], 0.0).is_none());
        let centre = 128.0 * ew;
        let viewer = DVec3::new(centre, centre, bounds.get(4, 4)[1] as f64 + 50.0);
        // The one smallest spacing (east-west, as drawn) on both axes, against per axis.
        let one = select_levels(&bounds, ew, [stretch[0]; 2], viewer, 2.0);
        let axis = select_levels(&bounds, ew, stretch, viewer, 2.0);
        let coarser = one.iter().zip(&axis).filter(|(o, a)| a > o).count();
        assert!(
            one.iter().zip(&axis).all(|(o, a)| a >= o),
            "a block got finer"
        );
        assert!(coarser > 0, "no block got coarser: {one:?}");
        // The blocks due east and due west of the viewer (same rows) keep their levels where
        // the east-west stretch is ~1; the north-south column changes.
        let cols = bounds.cols as usize;
        let column: Vec<_> = (0..bounds.rows as usize)
            .map(|j| j * cols + cols / 2)
            .collect();
        assert!(
            column.iter().any(|&k| axis[k] > one[k]),
            "north-south unchanged"
        );
    }

    #[test]
    fn neighbouring_levels_differ_by_at_most_one() {
        let data =
            crate::dataset::procedural::generate(&crate::dataset::procedural::ProceduralParams {
                size: 257,
                spacing: 30.0,
                ..Default::default()
            })
            .unwrap();
        let bounds = BlockBounds::new(&data, BLOCK_QUADS).unwrap();
        let viewer = DVec3::new(10.0, 20.0, bounds.get(0, 0)[1] as f64);
        let levels = select_levels(&bounds, 30.0, [1.0, 1.0], viewer, 0.3);
        let (cols, rows) = (bounds.cols, bounds.rows);
        assert!(levels.contains(&0) && levels.iter().any(|&l| l >= 2));
        for j in 0..rows {
            for i in 0..cols {
                let l = levels[(j * cols + i) as usize] as i64;
                if i + 1 < cols {
                    assert!((l - levels[(j * cols + i + 1) as usize] as i64).abs() <= 1);
                }
                if j + 1 < rows {
                    assert!((l - levels[((j + 1) * cols + i) as usize] as i64).abs() <= 1);
                }
            }
        }
    }
}
