//! The exact surface on the GPU: level 0 of the data, whichever way the renderer gets its
//! heights (one texture, or the clipmap's atlas of mixed levels), held as tiles of
//! `EVAL_REF_TILE + 1` samples per side around the views. Per frame the host selects the tiles
//! every view's frustum can see (quadtree descent over tile boxes spanning the data's height
//! range), reads the missing ones from level 0 ([`Terrain`]: the grid in memory, or the tile
//! pyramid through the same bounded [`crate::dataset::PyramidReader`] the clipmap path uses),
//! uploads them into a fixed-capacity atlas (least recently used tiles make room) and writes the
//! tile table the shader looks them up in. The reference never depends on an LOD or on what
//! the clipmap happens to have resident.
//!
//! Used between frames only, while no evaluated frame is in flight (the evaluator renders one
//! frame at a time), so host writes never race the GPU.

use std::collections::HashMap;
use std::sync::Arc;

use ash::vk;
use glam::DVec3;
use gpu_allocator::MemoryLocation;

use crate::dataset::{Level0, Terrain};
use crate::driver::Gpu;
use crate::driver::memory::Buffer;
use crate::error::{Error, Result};
use crate::geo::Lattice;
use crate::gpu_constants::EVAL_REF_TILE;
use crate::scene::Camera;

/// Samples per side a tile stores (its own `EVAL_REF_TILE` plus the first of the next tile).
pub const TILE_SIDE: u32 = EVAL_REF_TILE + 1;
const TILE_BYTES: u64 = (TILE_SIDE * TILE_SIDE * 4) as u64;
/// Table entry of a tile that is not resident.
const NO_TILE: u32 = u32::MAX;

/// A camera and the aspect ratio of the columns it is drawn into.
#[derive(Clone, Copy, Debug)]
pub struct ViewCone {
    pub camera: Camera,
    pub aspect: f64,
}

pub struct ReferenceSurface {
    data: Terrain,
    tiles: (u32, u32),
    capacity: u32,
    /// Heights range of the data widened by a margin (a method's surface may leave it a little).
    z_range: (f64, f64),
    pub atlas: Buffer,
    pub table: Buffer,
    staging: Option<Buffer>,
    gpu: Arc<Gpu>,
    /// Tile key held by each atlas slot, and the frame that last needed it.
    slots: Vec<Option<(u32, u32)>>,
    last_used: Vec<u64>,
    slot_of: HashMap<(u32, u32), u32>,
    table_host: Vec<u32>,
    /// Tiles read from level 0 so far.
    pub tiles_loaded: u64,
    /// On the earth: each tile's world box (row-major over the tiles), see [`earth_boxes`].
    earth: Option<Vec<(DVec3, DVec3)>>,
}

impl ReferenceSurface {
    /// Tiles over `data` in an atlas of at most `budget_bytes` (and the device's storage-buffer
    /// range); never more than the data has. `lattice`: where the renderers place the terrain
    /// on the earth (None: the flat world); tiles are then selected by their curved boxes.
    pub fn new(
        gpu: &Arc<Gpu>,
        data: &Terrain,
        lattice: Option<&Lattice>,
        budget_bytes: u64,
    ) -> Result<Self> {
        let tiles = (
            (data.width() - 1).div_ceil(EVAL_REF_TILE),
            (data.height() - 1).div_ceil(EVAL_REF_TILE),
        );
        let total = tiles.0 as u64 * tiles.1 as u64;
        let limit = budget_bytes.min(gpu.info.limits.max_storage_buffer_range as u64);
        let capacity = total.min(limit / TILE_BYTES) as u32;
        if capacity == 0 {
            return Err(Error::invalid(
                "eval reference",
                format!("a budget of {budget_bytes} bytes holds no {TILE_SIDE}x{TILE_SIDE} tile"),
            ));
        }
        let atlas = Buffer::new(
            gpu,
            "eval reference tiles",
            capacity as u64 * TILE_BYTES,
            vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuOnly,
        )?;
        let mut table = Buffer::new(
            gpu,
            "eval reference table",
            total * 4,
            vk::BufferUsageFlags::STORAGE_BUFFER,
            MemoryLocation::CpuToGpu,
        )?;
        let table_host = vec![NO_TILE; total as usize];
        table.write(bytemuck::cast_slice(&table_host))?;
        let (lo, hi) = data.height_range();
        let margin = 0.1 * (hi - lo) as f64 + 100.0;
        let z_range = (lo as f64 - margin, hi as f64 + margin);
        Ok(ReferenceSurface {
            earth: lattice.map(|l| earth_boxes(l, tiles, (data.width(), data.height()), z_range)),
            data: data.clone(),
            tiles,
            capacity,
            z_range,
            atlas,
            table,
            staging: None,
            gpu: gpu.clone(),
            slots: vec![None; capacity as usize],
            last_used: vec![0; capacity as usize],
            slot_of: HashMap::new(),
            table_host,
            tiles_loaded: 0,
        })
    }

    /// Reference tiles per side.
    pub fn tiles(&self) -> (u32, u32) {
        self.tiles
    }

    pub fn capacity(&self) -> u32 {
        self.capacity
    }

    /// Makes every tile the views of frame `frame` can see resident (the GPU must not be using
    /// the atlas or the table: no evaluated frame in flight).
    pub fn prepare(&mut self, frame: u64, views: &[ViewCone]) -> Result<()> {
        let mut needed: Vec<(u32, u32)> = Vec::new();
        for v in views {
            needed.extend(self.visible_tiles(v));
        }
        needed.sort_unstable();
        needed.dedup();
        if needed.len() > self.capacity as usize {
            return Err(Error::invalid(
                "eval reference",
                format!(
                    "frame {frame} sees {} level-0 tiles of {EVAL_REF_TILE}² samples, more than the {} the reference holds; raise --reference-mib",
                    needed.len(),
                    self.capacity
                ),
            ));
        }
        let mut missing = Vec::new();
        for &key in &needed {
            match self.slot_of.get(&key) {
                Some(&s) => self.last_used[s as usize] = frame + 1,
                None => missing.push(key),
            }
        }
        if missing.is_empty() {
            return Ok(());
        }
        // Free slots first, then the least recently used ones not needed now.
        let mut order: Vec<u32> = (0..self.capacity).collect();
        order.sort_by_key(|&s| (self.slots[s as usize].is_some(), self.last_used[s as usize]));
        let mut staged = vec![0f32; missing.len() * (TILE_SIDE * TILE_SIDE) as usize];
        let mut copies = Vec::with_capacity(missing.len());
        for (i, (&key, &slot)) in missing.iter().zip(&order).enumerate() {
            if self.last_used[slot as usize] == frame + 1 {
                return Err(Error::invalid("eval reference", "tile slots exhausted"));
            }
            if let Some(old) = self.slots[slot as usize].take() {
                self.slot_of.remove(&old);
                self.table_host[(old.1 * self.tiles.0 + old.0) as usize] = NO_TILE;
            }
            let n = (TILE_SIDE * TILE_SIDE) as usize;
            load_tile(&self.data, key, &mut staged[i * n..(i + 1) * n])?;
            self.slots[slot as usize] = Some(key);
            self.last_used[slot as usize] = frame + 1;
            self.slot_of.insert(key, slot);
            self.table_host[(key.1 * self.tiles.0 + key.0) as usize] = slot;
            copies.push(vk::BufferCopy {
                src_offset: i as u64 * TILE_BYTES,
                dst_offset: slot as u64 * TILE_BYTES,
                size: TILE_BYTES,
            });
        }
        self.tiles_loaded += missing.len() as u64;
        self.upload(bytemuck::cast_slice(&staged), &copies)?;
        self.table.write(bytemuck::cast_slice(&self.table_host))
    }

    fn upload(&mut self, bytes: &[u8], copies: &[vk::BufferCopy]) -> Result<()> {
        if self
            .staging
            .as_ref()
            .is_none_or(|s| s.size < bytes.len() as u64)
        {
            self.staging = Some(Buffer::new(
                &self.gpu,
                "eval reference staging",
                bytes.len() as u64,
                vk::BufferUsageFlags::TRANSFER_SRC,
                MemoryLocation::CpuToGpu,
            )?);
        }
        let staging = self.staging.as_mut().expect("staging allocated above");
        staging.write(bytes)?;
        let (src, dst) = (staging.raw, self.atlas.raw);
        // Waits: the next frame's analysis starts with a barrier after everything earlier.
        self.gpu
            .one_shot(|cmd| unsafe { self.gpu.device.cmd_copy_buffer(cmd, src, dst, copies) })
    }

    /// The tiles whose boxes (their samples widened by one, the data's widened height range)
    /// intersect the view's frustum: a quadtree descent from the whole tile grid; on the earth
    /// every tile's curved box ([`earth_boxes`]).
    pub fn visible_tiles(&self, view: &ViewCone) -> Vec<(u32, u32)> {
        let frustum = Frustum::of(view);
        if let Some(boxes) = &self.earth {
            return (0..self.tiles.1)
                .flat_map(|ty| (0..self.tiles.0).map(move |tx| (tx, ty)))
                .zip(boxes)
                .filter(|(_, (lo, hi))| frustum.touches(*lo, *hi))
                .map(|(key, _)| key)
                .collect();
        }
        let spacing = self.data.spacing();
        let side = EVAL_REF_TILE as f64 * spacing;
        let mut out = Vec::new();
        let mut stack = vec![(0u32, 0u32, self.tiles.0, self.tiles.1)];
        while let Some((x0, y0, x1, y1)) = stack.pop() {
            let lo = DVec3::new(
                x0 as f64 * side - spacing,
                y0 as f64 * side - spacing,
                self.z_range.0,
            );
            let hi = DVec3::new(
                x1 as f64 * side + spacing,
                y1 as f64 * side + spacing,
                self.z_range.1,
            );
            if !frustum.touches(lo, hi) {
                continue;
            }
            if x1 - x0 == 1 && y1 - y0 == 1 {
                out.push((x0, y0));
            } else if x1 - x0 >= y1 - y0 {
                let xm = (x0 + x1) / 2;
                stack.push((x0, y0, xm, y1));
                stack.push((xm, y0, x1, y1));
            } else {
                let ym = (y0 + y1) / 2;
                stack.push((x0, y0, x1, ym));
                stack.push((x0, ym, x1, y1));
            }
        }
        out
    }
}

/// On the earth, the world box of every reference tile (row-major over `tiles`): the box of
/// the lattice nodes of every lattice cell a sample position of the tile widened by one sample
/// lies in, each node at the lowest and the highest height of `z_range` along its up vector,
/// grown by two of the largest node spacing. The renderers' surface over a lattice cell is
/// the bilinear blend of its corners plus height times the blended up vector, a convex
/// combination of the corners' `p + h u`, so it lies inside the box of those (no sagitta
/// term needed); the growth covers the one-sample widening's extrapolation at the data's
/// edges. Computed once; the frustum then tests each tile's box (O(tiles) per view).
pub fn earth_boxes(
    lattice: &Lattice,
    tiles: (u32, u32),
    (width, height): (u32, u32),
    z_range: (f64, f64),
) -> Vec<(DVec3, DVec3)> {
    let step = lattice.step as i64;
    let last = [lattice.nodes[0] as i64 - 1, lattice.nodes[1] as i64 - 1];
    // The lattice cell of a sample index, clamped like the shaders'.
    let cell = |s: i64, axis: usize| s.div_euclid(step).clamp(0, last[axis] - 1);
    let mut grow: f64 = 0.0;
    for j in 0..=last[1] {
        for i in 0..=last[0] {
            let p = lattice.node_position(i, j).0;
            if i < last[0] {
                grow = grow.max((lattice.node_position(i + 1, j).0 - p).length());
            }
            if j < last[1] {
                grow = grow.max((lattice.node_position(i, j + 1).0 - p).length());
            }
        }
    }
    // Two samples' worth of the widest lattice edge.
    let grow = DVec3::splat(2.0 * grow / step as f64);
    let mut out = Vec::with_capacity(tiles.0 as usize * tiles.1 as usize);
    for ty in 0..tiles.1 as i64 {
        for tx in 0..tiles.0 as i64 {
            let c0 = tx * EVAL_REF_TILE as i64 - 1;
            let r0 = ty * EVAL_REF_TILE as i64 - 1;
            let c1 = (c0 + EVAL_REF_TILE as i64 + 2).min(width as i64);
            let r1 = (r0 + EVAL_REF_TILE as i64 + 2).min(height as i64);
            let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
            for j in cell(r0, 1)..=cell(r1, 1) + 1 {
                for i in cell(c0, 0)..=cell(c1, 0) + 1 {
                    let (p, u) = lattice.node_position(i, j);
                    for z in [z_range.0, z_range.1] {
                        lo = lo.min(p + u * z);
                        hi = hi.max(p + u * z);
                    }
                }
            }
            out.push((lo - grow, hi + grow));
        }
    }
    out
}

/// Level-0 samples of tile `key` (`TILE_SIDE`² heights, rows from the south; samples past the
/// data repeat its last row or column, never read by the shader).
fn load_tile(data: &Terrain, key: (u32, u32), out: &mut [f32]) -> Result<()> {
    let (w, h) = (data.width(), data.height());
    let c0 = key.0 * EVAL_REF_TILE;
    let c1 = (c0 + EVAL_REF_TILE).min(w - 1);
    let r0 = key.1 * EVAL_REF_TILE;
    let side = TILE_SIDE as usize;
    let mut row = Vec::with_capacity(side);
    let mut read = |level0: &dyn Level0| -> Result<()> {
        for j in 0..TILE_SIDE {
            let r = (r0 + j).min(h - 1);
            level0.row(r, c0, c1, &mut row)?;
            let dst = &mut out[j as usize * side..(j as usize + 1) * side];
            let n = row.len();
            dst[..n].copy_from_slice(&row);
            let last = row[n - 1];
            dst[n..].fill(last);
        }
        Ok(())
    };
    match data {
        Terrain::Grid(grid) => read(&**grid),
        Terrain::Pyramid(pyramid) => read(&pyramid.sweep()),
    }
}

/// A view frustum as inward half-spaces `n . (p - eye) + d >= 0`.
struct Frustum {
    eye: DVec3,
    planes: [(DVec3, f64); 6],
}

impl Frustum {
    fn of(view: &ViewCone) -> Self {
        let c = &view.camera;
        let (right, up, forward) = c.basis();
        let tan_v = (c.vfov_deg.to_radians() / 2.0).tan();
        let tan_h = tan_v * view.aspect;
        Frustum {
            eye: c.position,
            planes: [
                (forward, -c.near),
                (-forward, c.far),
                (forward * tan_h - right, 0.0),
                (forward * tan_h + right, 0.0),
                (forward * tan_v - up, 0.0),
                (forward * tan_v + up, 0.0),
            ],
        }
    }

    /// Whether the box `lo..hi` may intersect the frustum (conservative: a box outside no
    /// single plane is kept).
    fn touches(&self, lo: DVec3, hi: DVec3) -> bool {
        self.planes.iter().all(|&(n, d)| {
            // The corner farthest along n.
            let corner = DVec3::new(
                if n.x >= 0.0 { hi.x } else { lo.x },
                if n.y >= 0.0 { hi.y } else { lo.y },
                if n.z >= 0.0 { hi.z } else { lo.z },
            );
            n.dot(corner - self.eye) + d >= 0.0
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geo::{EnuFrame, Geodetic, WGS84};
    use glam::DVec2;

    /// Every point of the lattice surface over a tile, at any height of the range, lies in the
    /// tile's earth box; negative control: boxes built for height 0 only miss raised points.
    #[test]
    fn earth_boxes_hold_the_curved_surface() {
        let frame = EnuFrame::new(&WGS84, Geodetic::new(46.5, 8.0, 0.0));
        let (w, h) = (300u32, 200u32);
        let lattice = Lattice::anchored_plane(w, h, 200.0, frame).unwrap();
        let tiles = (
            (w - 1).div_ceil(EVAL_REF_TILE),
            (h - 1).div_ceil(EVAL_REF_TILE),
        );
        let boxes = earth_boxes(&lattice, tiles, (w, h), (-50.0, 3000.0));
        let flat = earth_boxes(&lattice, tiles, (w, h), (0.0, 0.0));
        let inside = |b: &(DVec3, DVec3), p: DVec3| p.cmpge(b.0).all() && p.cmple(b.1).all();
        let mut missed_by_flat = 0;
        for j in 0..60 {
            for i in 0..90 {
                let s = DVec2::new(i as f64 * 3.31 + 0.2, j as f64 * 3.29 + 0.4);
                let key = (s.x as u32 / EVAL_REF_TILE, s.y as u32 / EVAL_REF_TILE);
                let k = (key.1 * tiles.0 + key.0) as usize;
                for z in [-50.0, 0.0, 1234.5, 3000.0] {
                    let p = lattice.position(s, z);
                    assert!(inside(&boxes[k], p), "{s} at {z} m outside {:?}", boxes[k]);
                    missed_by_flat += usize::from(!inside(&flat[k], p));
                }
            }
        }
        assert!(missed_by_flat > 1000, "{missed_by_flat}");
        // The far corner (60 x 40 km from the origin) curves ~100 m below the tangent plane.
        let last = boxes.last().unwrap();
        assert!(last.0.z < -100.0, "{last:?}");
    }

    /// The frustum test keeps every point a camera sees and drops what is behind it.
    #[test]
    fn frustum_keeps_what_the_camera_sees() {
        let camera = Camera {
            position: DVec3::new(500.0, 300.0, 800.0),
            yaw_deg: 40.0,
            pitch_deg: -35.0,
            vfov_deg: 45.0,
            near: 1.0,
            far: 4000.0,
            ..Camera::default()
        };
        let view = ViewCone {
            camera,
            aspect: 16.0 / 9.0,
        };
        let f = Frustum::of(&view);
        let (w, h) = (320u32, 180u32);
        let (_, _, fwd) = camera.basis();
        for y in (0..h).step_by(7) {
            for x in (0..w).step_by(11) {
                let ray = camera.pixel_ray(x as f64 + 0.5, y as f64 + 0.5, w, h);
                for along in [1.5, 100.0, 3990.0] {
                    let p = camera.position + ray * (along / ray.dot(fwd));
                    let e = DVec3::splat(1e-3);
                    assert!(f.touches(p - e, p + e), "pixel ({x}, {y}) at {along} m");
                }
            }
        }
        // Negative controls: behind the camera, beyond the far plane, off to the side.
        let behind = camera.position - fwd * 50.0;
        assert!(!f.touches(behind - DVec3::ONE, behind + DVec3::ONE));
        let beyond = camera.position + fwd * 5000.0;
        assert!(!f.touches(beyond - DVec3::ONE, beyond + DVec3::ONE));
        let (right, _, _) = camera.basis();
        let side = camera.position + fwd * 100.0 + right * 400.0;
        assert!(!f.touches(side - DVec3::ONE, side + DVec3::ONE));
    }
}
