//! Chunked LOD on the CPU: the reference of the GPU's chunk selection (screen-space error of a
//! chunk's bounding sphere, sphere frustum culling), the LOD map the vertex stage stitches
//! with, and the concurrent binary tree's layout (memory against depth, initial state).
//!
//! Arithmetic that must agree with `shaders/include/chunked_common.wgsl` (`chunk_sphere`,
//! `chunk_splits`, `chunk_culled`) is written in f32 in the same order; `tests/chunked.rs`
//! compares the GPU's render list against [`select_chunks`].

use std::sync::Arc;

use glam::{DVec3, Vec3};

use super::settings::ChunkedSettings;
use crate::geo::{EarthCull, Lattice};
use crate::lod::udlod::levels::{Levels, Tile};
use crate::lod::udlod::params::{frustum_planes, stretch_at_viewer};
use crate::scene::Camera;

/// The levels a walk visits: it starts at `start` (the root depth below the root) and never
/// splits below `finest` (the tree depth below the root).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Depths {
    pub root: u32,
    pub start: u32,
    pub finest: u32,
}

impl Depths {
    pub fn new(levels: &Levels, settings: &ChunkedSettings) -> Self {
        let root = levels.root_lod;
        let depth = settings.max_depth.min(root);
        let finest = root - depth;
        let start = root - settings.root_depth.min(depth);
        Depths {
            root,
            start,
            finest,
        }
    }

    /// Quadtree levels below the root the tree can hold.
    pub fn tree_depth(&self) -> u32 {
        self.root - self.finest
    }
}

/// Per-frame inputs of the selection, exactly as the GPU gets them.
#[derive(Clone, Debug)]
pub struct ChunkParams {
    pub camera_cell: [i32; 2],
    /// Camera position inside its cell (metres) and its height.
    pub camera_offset: [f32; 2],
    pub camera_z: f32,
    /// The LOD viewer relative to the camera (metres).
    pub viewer: [f32; 3],
    pub spacing: f32,
    /// The LOD metric's stretch of the grid frame per axis ([`Levels::stretch`]): exactly
    /// `[1, 1]` on square grids, whose chunks split by their bounding spheres; otherwise by
    /// the distance to their box in the stretched metric ([`chunk_box_distance`]).
    pub stretch: [f32; 2],
    pub frustum: [[f32; 4]; 6],
    pub cull: bool,
    /// On the earth: the lattice and the camera's world position; chunks are then culled
    /// with the curved boxes instead of the flat world's bounding spheres (None: flat).
    pub earth: Option<EarthCull>,
    pub error_px: f32,
    pub focal_px: f32,
    pub depths: Depths,
}

impl ChunkParams {
    pub fn new(
        levels: &Levels,
        settings: &ChunkedSettings,
        camera: &Camera,
        lod_viewer: DVec3,
        width: u32,
        height: u32,
    ) -> Self {
        let s = levels.spacing;
        let (cx, cy) = (
            (camera.position.x / s).floor(),
            (camera.position.y / s).floor(),
        );
        let v = lod_viewer - camera.position;
        ChunkParams {
            camera_cell: [cx as i32, cy as i32],
            camera_offset: [
                (camera.position.x - cx * s) as f32,
                (camera.position.y - cy * s) as f32,
            ],
            camera_z: camera.position.z as f32,
            viewer: [v.x as f32, v.y as f32, v.z as f32],
            spacing: s as f32,
            stretch: levels.stretch(),
            frustum: frustum_planes(camera, width as f64 / height as f64),
            cull: settings.cull,
            earth: None,
            error_px: settings.error_px as f32,
            focal_px: camera.focal_px(height) as f32,
            depths: Depths::new(levels, settings),
        }
    }

    /// These inputs on the earth: chunks are culled with the curved boxes of `lattice`
    /// (`camera`: the camera's world position, as the frame uniforms carry it). On a native
    /// non-square grid the per-axis stretch is also lowered to the lattice's spacing at the
    /// LOD viewer where that is smaller ([`Lattice::stretch_at`]). Square grids keep `[1, 1]`.
    pub fn on_earth(mut self, levels: &Levels, lattice: Arc<Lattice>, camera: DVec3) -> Self {
        self.stretch = stretch_at_viewer(levels, &lattice, self.stretch, camera, self.viewer);
        self.earth = Some(EarthCull::new(lattice, camera));
        self
    }

    /// Camera-relative metres of a sample position (`relative_xy` in the shaders).
    pub fn relative(&self, sample: [i32; 2]) -> [f32; 2] {
        [
            (sample[0] - self.camera_cell[0]) as f32 * self.spacing - self.camera_offset[0],
            (sample[1] - self.camera_cell[1]) as f32 * self.spacing - self.camera_offset[1],
        ]
    }
}

/// A chunk's bounding sphere, camera-relative: the sphere around its box (rectangle clamped
/// to the data x its min/max height). Returns (centre, radius).
pub fn chunk_sphere(levels: &Levels, p: &ChunkParams, t: Tile) -> (Vec3, f32) {
    let (lo, hi) = chunk_rect(levels, p, t);
    let [zmin, zmax] = levels.tile_min_max(t);
    let centre = Vec3::new(
        (lo[0] + hi[0]) * 0.5,
        (lo[1] + hi[1]) * 0.5,
        (zmin + zmax) * 0.5 - p.camera_z,
    );
    let half = Vec3::new(
        (hi[0] - lo[0]) * 0.5,
        (hi[1] - lo[1]) * 0.5,
        (zmax - zmin) * 0.5,
    );
    (centre, half.length())
}

/// The chunk's rectangle (clamped to the data), camera-relative grid-frame metres: `(lo, hi)`.
fn chunk_rect(levels: &Levels, p: &ChunkParams, t: Tile) -> ([f32; 2], [f32; 2]) {
    let span = (levels.grid_size << t.lod) as i32;
    let (w, h) = (levels.width as i32 - 1, levels.height as i32 - 1);
    let lo = p.relative([t.x as i32 * span, t.y as i32 * span]);
    let hi = p.relative([
        ((t.x as i32 + 1) * span).min(w),
        ((t.y as i32 + 1) * span).min(h),
    ]);
    (lo, hi)
}

/// Distance from the LOD viewer to the chunk's box (its rectangle clamped to the data x its
/// min/max height) in the LOD metric: grid-frame offsets times [`ChunkParams::stretch`] per
/// axis, heights as they are (`chunk_box_distance` in `shaders/chunked_select.wgsl`, the same
/// f32 operations). Each axis's stretch is the smallest metres per sample on the drawn
/// surface ([`crate::geo::Lattice::min_axis_spacing`]), so this is a lower bound of the
/// distance to the chunk's terrain (tests/chunked.rs checks it against true chords).
pub fn chunk_box_distance(levels: &Levels, p: &ChunkParams, t: Tile) -> f32 {
    let (lo, hi) = chunk_rect(levels, p, t);
    let [zmin, zmax] = levels.tile_min_max(t);
    let v = p.viewer;
    let dx = (lo[0] - v[0]).max(0.0f32.min(hi[0] - v[0])) * p.stretch[0];
    let dy = (lo[1] - v[1]).max(0.0f32.min(hi[1] - v[1])) * p.stretch[1];
    let dz = (zmin - p.camera_z - v[2]).max(0.0f32.min(zmax - p.camera_z - v[2]));
    Vec3::new(dx, dy, dz).length()
}

/// Does the chunk split? Its geometric error (metres, the data's tile statistics) projected
/// at its distance from the LOD viewer exceeds the pixel threshold:
/// `error * focal > threshold * distance` (no division; inside always, unless the chunk has
/// no error). The distance: to its bounding sphere on square grids (stretch `[1, 1]`), to its
/// box in the per-axis LOD metric on native non-square ones ([`chunk_box_distance`]; a
/// sphere around a stretched box grows with the stretch, docs/chunked.md). Never below the
/// finest level.
pub fn chunk_splits(levels: &Levels, p: &ChunkParams, t: Tile) -> bool {
    if t.lod <= p.depths.finest {
        return false;
    }
    let d = if p.stretch == [1.0, 1.0] {
        let (c, r) = chunk_sphere(levels, p, t);
        let to = c - Vec3::from(p.viewer);
        (to.length() - r).max(0.0)
    } else {
        chunk_box_distance(levels, p, t)
    };
    levels.tile_error(t) * p.focal_px > p.error_px * d
}

/// Is the chunk's bounding sphere wholly outside one frustum plane? On the earth: is its
/// curved box ([`EarthCull::outside`], UDLOD's box with UDLOD's margin of 1e-3 of the chunk's
/// side; f64, deciding as the GPU's f32 `earth_box` except within the GPU's rounding of the
/// boundary, which tests/chunked.rs brackets)?
pub fn chunk_culled(levels: &Levels, p: &ChunkParams, t: Tile) -> bool {
    if let Some(earth) = &p.earth {
        let span = (levels.grid_size << t.lod) as i32;
        let (w, h) = (levels.width as i32 - 1, levels.height as i32 - 1);
        let c0 = [t.x as i32 * span, t.y as i32 * span];
        let c1 = [(c0[0] + span).min(w), (c0[1] + span).min(h)];
        let margin = 1e-3 * (span as f32 * p.spacing);
        return earth.outside(&p.frustum, c0, c1, levels.tile_min_max(t), margin as f64);
    }
    let (c, r) = chunk_sphere(levels, p, t);
    p.frustum
        .iter()
        .any(|pl| pl[0] * c.x + pl[1] * c.y + pl[2] * c.z + pl[3] < -r)
}

/// The chunks of the start level that touch the data (the first traversal list).
pub fn start_chunks(levels: &Levels, depths: Depths) -> Vec<Tile> {
    let (nx, ny) = levels.tiles_per_side[depths.start as usize];
    (0..ny)
        .flat_map(|y| {
            (0..nx).map(move |x| Tile {
                x,
                y,
                lod: depths.start,
            })
        })
        .collect()
}

/// The four children of a chunk, in the CBT's order (x bit first).
pub fn children(t: Tile) -> [Tile; 4] {
    std::array::from_fn(|k| Tile {
        x: t.x * 2 + (k as u32 & 1),
        y: t.y * 2 + (k as u32 >> 1),
        lod: t.lod - 1,
    })
}

/// The reference selection (the naive traversal without capacity limits): the chunks drawn.
pub fn select_chunks(levels: &Levels, p: &ChunkParams) -> Vec<Tile> {
    let mut out = Vec::new();
    let mut layer = start_chunks(levels, p.depths);
    while !layer.is_empty() {
        let mut next = Vec::new();
        for t in layer {
            if !levels.inside(t) || (p.cull && chunk_culled(levels, p, t)) {
                continue;
            }
            if chunk_splits(levels, p, t) {
                next.extend(children(t));
            } else {
                out.push(t);
            }
        }
        layer = next;
    }
    out
}

/// The LOD map: per cell of level 0's chunk grid, the level of the drawn chunk covering it
/// (0 where none is drawn: culled or outside), row-major over `tiles_per_side[0]`.
pub fn lod_map(levels: &Levels, chunks: &[Tile]) -> Vec<u32> {
    let (nx, ny) = levels.tiles_per_side[0];
    let mut map = vec![0; (nx * ny) as usize];
    for t in chunks {
        let side = 1u32 << t.lod;
        for j in 0..side {
            for i in 0..side {
                let (cx, cy) = ((t.x << t.lod) + i, (t.y << t.lod) + j);
                if cx < nx && cy < ny {
                    map[(cy * nx + cx) as usize] = t.lod;
                }
            }
        }
    }
    map
}

/// The sample vertex `local` of chunk `t` stands on after edge patching, before clamping to
/// the data: the CPU mirror of `chunk_sample` (`shaders/include/chunked_sample.wgsl` and its
/// GLSL port), the same integer operations, with `map` the LOD map ([`lod_map`]).
pub fn chunk_sample(
    levels: &Levels,
    map: &[u32],
    t: Tile,
    local: [u32; 2],
    stitch: bool,
) -> [i32; 2] {
    let quads = levels.grid_size;
    let mut s = [
        ((t.x * quads + local[0]) << t.lod) as i32,
        ((t.y * quads + local[1]) << t.lod) as i32,
    ];
    if !stitch {
        return s;
    }
    let (nx, ny) = levels.tiles_per_side[0];
    let level_at = |c: [i32; 2]| -> u32 {
        if c[0] < 0 || c[1] < 0 || c[0] >= nx as i32 || c[1] >= ny as i32 {
            0
        } else {
            map[(c[1] as u32 * nx + c[0] as u32) as usize]
        }
    };
    let side = 1i32 << t.lod;
    let lo = [t.x as i32 * side, t.y as i32 * side];
    let cell = [0, 1].map(|i| (s[i] / quads as i32).clamp(lo[i], lo[i] + side - 1));
    // Axis 0 edges (west/east) snap y; axis 1 edges (south/north) snap x.
    for (axis, along) in [(0usize, 1usize), (1, 0)] {
        if local[axis] == 0 || local[axis] == quads {
            let across = if local[axis] == 0 {
                lo[axis] - 1
            } else {
                lo[axis] + side
            };
            let mut c = cell;
            c[axis] = across;
            let l = level_at(c);
            if l > t.lod {
                s[along] = (s[along] >> l) << l;
            }
        }
    }
    s
}

/// The largest level difference between two drawn chunks that share an edge (edge patching
/// is exact up to log2(chunk_quads); beyond, Hedberg: "cannot be guaranteed").
pub fn largest_level_jump(levels: &Levels, chunks: &[Tile]) -> u32 {
    let (nx, ny) = levels.tiles_per_side[0];
    let map = lod_map(levels, chunks);
    let mut drawn = vec![false; map.len()];
    for t in chunks {
        let side = 1u32 << t.lod;
        for j in 0..side {
            for i in 0..side {
                let (cx, cy) = ((t.x << t.lod) + i, (t.y << t.lod) + j);
                if cx < nx && cy < ny {
                    drawn[(cy * nx + cx) as usize] = true;
                }
            }
        }
    }
    let mut jump = 0;
    for y in 0..ny {
        for x in 0..nx {
            let k = (y * nx + x) as usize;
            for (n, ok) in [(k + 1, x + 1 < nx), (k + nx as usize, y + 1 < ny)] {
                if ok && drawn[k] && drawn[n] {
                    jump = jump.max(map[k].abs_diff(map[n]));
                }
            }
        }
    }
    jump
}

/// The concurrent binary tree over a quadtree `quad_depth` levels deep: a binary tree of depth
/// `2 quad_depth` (every quadtree split is two binary splits, x then y), stored as a bit field
/// of its `2^D` deepest nodes and a sum-reduction heap of u32 over the `2^D - 1` nodes above
/// (heap index 1 the root, children `2k` and `2k + 1`; index 0 unused).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CbtLayout {
    /// Binary depth `D`.
    pub depth: u32,
}

impl CbtLayout {
    pub fn for_quad_depth(quad_depth: u32) -> Self {
        CbtLayout {
            depth: 2 * quad_depth,
        }
    }

    /// Bytes of the sum-reduction heap (u32 per node above the bit field, index 0 unused).
    pub fn heap_bytes(&self) -> u64 {
        4u64 << self.depth
    }

    /// Bytes of the bit field (at least one u32 word).
    pub fn bit_bytes(&self) -> u64 {
        ((1u64 << self.depth) / 8).max(4)
    }

    pub fn total_bytes(&self) -> u64 {
        self.heap_bytes() + self.bit_bytes()
    }

    /// The bit of the leftmost deepest descendant of heap node `n` at binary depth `d`.
    pub fn leaf_bit(&self, n: u64, d: u32) -> u64 {
        (n << (self.depth - d)) - (1u64 << self.depth)
    }

    /// The initial tree: every node at quadtree depth `root_depth` a leaf. Returns (heap,
    /// bit words).
    pub fn initial(&self, root_depth: u32) -> (Vec<u32>, Vec<u32>) {
        let d = 2 * root_depth;
        let words = (self.bit_bytes() / 4) as usize;
        let mut bits = vec![0u32; words];
        for m in 0..(1u64 << d) {
            let b = self.leaf_bit((1u64 << d) + m, d);
            bits[(b / 32) as usize] |= 1 << (b % 32);
        }
        (self.reduce(&bits), bits)
    }

    /// The sum-reduction heap of a bit field.
    pub fn reduce(&self, bits: &[u32]) -> Vec<u32> {
        let n = 1usize << self.depth;
        let mut heap = vec![0u32; n];
        let bit = |b: usize| (bits[b / 32] >> (b % 32)) & 1;
        for k in (1..n).rev() {
            heap[k] = if 2 * k >= n {
                bit(2 * k - n) + bit(2 * k + 1 - n)
            } else {
                heap[2 * k] + heap[2 * k + 1]
            };
        }
        heap
    }

    /// The chunk of a node at even binary depth `2 k` (`k` quadtree levels below the root):
    /// its index below the root bit-interleaved, x in the even bits (split first).
    pub fn chunk(&self, n: u64, d: u32, root_lod: u32) -> Tile {
        let m = n - (1u64 << d);
        let (mut x, mut y) = (0u32, 0u32);
        for i in 0..d / 2 {
            x |= (((m >> (2 * i)) & 1) as u32) << i;
            y |= (((m >> (2 * i + 1)) & 1) as u32) << i;
        }
        Tile {
            x,
            y,
            lod: root_lod - d / 2,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hedberg's numbers: 16.8 MB of u32 sums at total depth 11 (binary depth 22), four times
    /// that one level deeper.
    #[test]
    fn cbt_memory_grows_fourfold_per_level() {
        let l = CbtLayout::for_quad_depth(11);
        assert_eq!(l.heap_bytes(), 16_777_216);
        assert_eq!(l.bit_bytes(), 524_288);
        assert_eq!(
            CbtLayout::for_quad_depth(12).heap_bytes(),
            4 * l.heap_bytes()
        );
    }

    #[test]
    fn initial_tree_holds_the_root_depth_chunks() {
        let l = CbtLayout::for_quad_depth(4);
        let (heap, bits) = l.initial(2);
        assert_eq!(heap[1], 16);
        // Control: a different root depth holds a different count.
        assert_eq!(l.initial(1).0[1], 4);
        // Node -> chunk is a bijection on the 16 chunks of depth 2.
        let mut seen: Vec<(u32, u32)> = (16..32)
            .map(|n| {
                let t = l.chunk(n, 4, 4);
                assert_eq!(t.lod, 2);
                (t.x, t.y)
            })
            .collect();
        seen.sort_unstable();
        seen.dedup();
        assert_eq!(seen.len(), 16);
        assert_eq!(bits.iter().map(|w| w.count_ones()).sum::<u32>(), 16);
        // The children of node n (4n + k) are the chunk's children in `children` order.
        let parent = l.chunk(21, 4, 4);
        for (k, c) in children(parent).iter().enumerate() {
            assert_eq!(l.chunk(4 * 21 + k as u64, 6, 4), *c);
        }
    }
}
