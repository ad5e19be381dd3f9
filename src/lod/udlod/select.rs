//! UDLOD on the CPU: the level structure, per-tile min/max heights, per-level geometric
//! errors, the split-distance table derived from the screen-space error target, the frustum,
//! the morph function, and a reference implementation of the GPU's tile selection (tests
//! compare the GPU's final tile list against it).
//!
//! Arithmetic that must agree with the shaders (`select_tiles`, `morph_factor`) is written in
//! f32 in the same order as `shaders/udlod_tiling.wgsl` and `shaders/udlod.wgsl`.

use glam::{DVec3, Vec3};

use crate::dataset::Heightmap;
use crate::gpu_constants::{UDLOD_MAX_LEVELS, UDLOD_NO_SPLIT};
use crate::scene::Camera;

/// A quadtree tile: `(x, y)` in tiles of its level, `lod` 0 = full resolution.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Tile {
    pub x: u32,
    pub y: u32,
    pub lod: u32,
}

/// The static structure of the quadtree over one data set.
#[derive(Clone, Debug)]
pub struct Levels {
    /// Quads per tile side.
    pub grid_size: u32,
    /// The root level: one tile covers the whole data set.
    pub root_lod: u32,
    pub width: u32,
    pub height: u32,
    pub spacing: f64,
    /// Tiles per side of each level (only tiles that touch the data).
    pub tiles_per_side: Vec<(u32, u32)>,
    /// Offset of each level's entries in `min_max`.
    pub level_offsets: Vec<u32>,
    /// (min, max) height in metres of every tile's samples (and of its morph targets, which are
    /// samples of the same tile).
    pub min_max: Vec<[f32; 2]>,
    /// Geometric error of each level in metres: the largest height difference between the
    /// full-resolution samples and the level's triangulated grid (0 for level 0).
    pub level_error: Vec<f64>,
}

impl Levels {
    pub fn new(data: &Heightmap, grid_size: u32) -> Self {
        let quads = (data.width - 1).max(data.height - 1);
        let mut root_lod = 0;
        while (grid_size << root_lod) < quads {
            root_lod += 1;
        }
        let mut tiles_per_side = Vec::new();
        let mut level_offsets = Vec::new();
        let mut min_max = Vec::new();
        for lod in 0..=root_lod {
            let span = grid_size << lod;
            let nx = (data.width - 1).div_ceil(span);
            let ny = (data.height - 1).div_ceil(span);
            tiles_per_side.push((nx, ny));
            level_offsets.push(min_max.len() as u32);
            for ty in 0..ny {
                for tx in 0..nx {
                    min_max.push(tile_min_max(data, tx * span, ty * span, span));
                }
            }
        }
        let level_error = (0..=root_lod).map(|lod| level_error(data, lod)).collect();
        Levels {
            grid_size,
            root_lod,
            width: data.width,
            height: data.height,
            spacing: data.spacing,
            tiles_per_side,
            level_offsets,
            min_max,
            level_error,
        }
    }

    pub fn levels(&self) -> u32 {
        self.root_lod + 1
    }

    /// Tile side in metres at `lod`.
    pub fn tile_extent(&self, lod: u32) -> f64 {
        (self.grid_size << lod) as f64 * self.spacing
    }

    pub fn tile_min_max(&self, t: Tile) -> [f32; 2] {
        let (nx, _) = self.tiles_per_side[t.lod as usize];
        self.min_max[(self.level_offsets[t.lod as usize] + t.y * nx + t.x) as usize]
    }

    /// Does the tile touch the data set?
    pub fn inside(&self, t: Tile) -> bool {
        let (nx, ny) = self.tiles_per_side[t.lod as usize];
        t.x < nx && t.y < ny
    }

    /// Split distance of each level (metres), see [`split_distances`].
    pub fn split_distances(&self, focal_px: f64, tau_px: f64, morph_range: f64) -> Vec<f32> {
        split_distances(self, focal_px, tau_px, morph_range)
    }
}

fn tile_min_max(data: &Heightmap, c0: u32, r0: u32, span: u32) -> [f32; 2] {
    let (c1, r1) = (
        (c0 + span).min(data.width - 1),
        (r0 + span).min(data.height - 1),
    );
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for r in r0..=r1 {
        for c in c0..=c1 {
            let h = data.sample(c, r);
            lo = lo.min(h);
            hi = hi.max(h);
        }
    }
    [lo, hi]
}

/// Height of the level-`lod` triangulated grid at full-resolution sample `(c, r)`. Quads are
/// split along the diagonal from (1, 0) to (0, 1), as `grid_indices` does.
fn level_height(data: &Heightmap, lod: u32, c: u32, r: u32) -> f64 {
    let step = 1u32 << lod;
    let s = |c: u32, r: u32| data.sample(c.min(data.width - 1), r.min(data.height - 1)) as f64;
    let (c0, r0) = (c / step * step, r / step * step);
    let (fx, fy) = ((c - c0) as f64 / step as f64, (r - r0) as f64 / step as f64);
    let (h00, h10, h01, h11) = (
        s(c0, r0),
        s(c0 + step, r0),
        s(c0, r0 + step),
        s(c0 + step, r0 + step),
    );
    if fx + fy <= 1.0 {
        h00 + (h10 - h00) * fx + (h01 - h00) * fy
    } else {
        h11 + (h01 - h11) * (1.0 - fx) + (h10 - h11) * (1.0 - fy)
    }
}

fn level_error(data: &Heightmap, lod: u32) -> f64 {
    if lod == 0 {
        return 0.0;
    }
    let mut worst = 0.0f64;
    for r in 0..data.height {
        for c in 0..data.width {
            worst = worst.max((level_height(data, lod, c, r) - data.sample(c, r) as f64).abs());
        }
    }
    worst
}

/// Split distance `D[lod]` (metres): a tile of level `lod` splits when the viewer is nearer
/// than that. Three constraints, all from the morph construction:
/// 1. screen error: a level-`l` tile is drawn at distances >= `(1 - morph_range) * D[l]`
///    at the least (inside its morph zone), where its geometric error `e[l]` must project to
///    at most `tau` pixels: `D[l] >= e[l] * focal / (tau * (1 - morph_range))`;
/// 2. crack-free: where a level-`l` tile meets a level `l - 1` tile it must not have started
///    morphing, i.e. `D[l] + sqrt(2) * extent(l) <= (1 - morph_range) * D[l + 1]`, which also
///    implies that neighbours differ by at most one level;
/// 3. `D[root + 1]` is infinite: the root level never morphs.
///
/// Entry `l` holds `D[l]`; entries past the root hold [`UDLOD_NO_SPLIT`].
pub fn split_distances(levels: &Levels, focal_px: f64, tau_px: f64, morph_range: f64) -> Vec<f32> {
    let keep = 1.0 - morph_range;
    let mut d = vec![UDLOD_NO_SPLIT as f64; UDLOD_MAX_LEVELS as usize];
    let mut prev: Option<f64> = None;
    for lod in 0..=levels.root_lod {
        let screen = levels.level_error[lod as usize] * focal_px / (tau_px * keep);
        let chain = match prev {
            Some(p) => (p + std::f64::consts::SQRT_2 * levels.tile_extent(lod - 1)) / keep,
            None => 0.0,
        };
        // Level 0 never splits, but its D anchors the chain (a floor of one tile extent keeps
        // level-1 tiles from being tiny when the data is smooth).
        let v = screen.max(chain).max(levels.tile_extent(lod));
        d[lod as usize] = v;
        prev = Some(v);
    }
    d.iter().map(|&v| v as f32).collect()
}

/// Frustum planes in camera-relative world space (metres), `(normal, offset)` with
/// `dot(normal, p) + offset >= 0` inside: left, right, bottom, top, near, far.
pub fn frustum_planes(camera: &Camera, aspect: f64) -> [[f32; 4]; 6] {
    let (right, up, forward) = camera.basis();
    let tan_y = (camera.vfov_deg.to_radians() / 2.0).tan();
    let tan_x = tan_y * aspect;
    let side = |edge: DVec3, axis: DVec3| -> [f32; 4] {
        // Plane through the origin containing `axis` and the edge direction; normal inwards.
        let n = edge.cross(axis).normalize();
        let n = if n.dot(forward) < 0.0 { -n } else { n };
        [n.x as f32, n.y as f32, n.z as f32, 0.0]
    };
    [
        side(forward - right * tan_x, up),
        side(forward + right * tan_x, up),
        side(forward - up * tan_y, right),
        side(forward + up * tan_y, right),
        {
            let f = forward.as_vec3();
            [f.x, f.y, f.z, -(camera.near as f32)]
        },
        {
            let f = -forward.as_vec3();
            [f.x, f.y, f.z, camera.far as f32]
        },
    ]
}

/// Per-frame inputs of the selection, exactly as the GPU gets them.
#[derive(Clone, Debug)]
pub struct SelectionParams {
    pub camera_cell: [i32; 2],
    /// Camera position inside its cell (metres) and its height.
    pub camera_offset: [f32; 2],
    pub camera_z: f32,
    /// Reference height for distances (terrain height under the viewer), metres.
    pub z_ref: f32,
    pub spacing: f32,
    pub split: Vec<f32>,
    pub frustum: [[f32; 4]; 6],
    pub cull: bool,
}

impl SelectionParams {
    pub fn new(
        levels: &Levels,
        data: &Heightmap,
        camera: &Camera,
        aspect: f64,
        split: Vec<f32>,
    ) -> Self {
        let s = levels.spacing;
        let (cx, cy) = (
            (camera.position.x / s).floor(),
            (camera.position.y / s).floor(),
        );
        SelectionParams {
            camera_cell: [cx as i32, cy as i32],
            camera_offset: [
                (camera.position.x - cx * s) as f32,
                (camera.position.y - cy * s) as f32,
            ],
            camera_z: camera.position.z as f32,
            z_ref: data.height_at(camera.position.x, camera.position.y) as f32,
            spacing: s as f32,
            split,
            frustum: frustum_planes(camera, aspect),
            cull: true,
        }
    }

    /// Camera-relative metres of a sample position (integer cell, as the shaders compute it).
    pub fn relative(&self, sample: [i32; 2]) -> [f32; 2] {
        [
            (sample[0] - self.camera_cell[0]) as f32 * self.spacing - self.camera_offset[0],
            (sample[1] - self.camera_cell[1]) as f32 * self.spacing - self.camera_offset[1],
        ]
    }
}

/// Distance from the viewer to the nearest point of the tile's rectangle at `z_ref`.
pub fn tile_distance(levels: &Levels, p: &SelectionParams, t: Tile) -> f32 {
    let span = (levels.grid_size << t.lod) as i32;
    let lo = p.relative([t.x as i32 * span, t.y as i32 * span]);
    let hi = p.relative([(t.x as i32 + 1) * span, (t.y as i32 + 1) * span]);
    let dx = lo[0].max(0.0f32.min(hi[0]));
    let dy = lo[1].max(0.0f32.min(hi[1]));
    let dz = p.z_ref - p.camera_z;
    Vec3::new(dx, dy, dz).length()
}

/// Is the tile's box (rectangle clamped to the data x min/max height) outside the frustum?
pub fn tile_culled(levels: &Levels, p: &SelectionParams, t: Tile) -> bool {
    let span = (levels.grid_size << t.lod) as i32;
    let (w, h) = (levels.width as i32 - 1, levels.height as i32 - 1);
    let lo = p.relative([t.x as i32 * span, t.y as i32 * span]);
    let hi = p.relative([
        ((t.x as i32 + 1) * span).min(w),
        ((t.y as i32 + 1) * span).min(h),
    ]);
    let [zmin, zmax] = levels.tile_min_max(t);
    let (zlo, zhi) = (zmin - p.camera_z, zmax - p.camera_z);
    p.frustum.iter().any(|pl| {
        let x = if pl[0] >= 0.0 { hi[0] } else { lo[0] };
        let y = if pl[1] >= 0.0 { hi[1] } else { lo[1] };
        let z = if pl[2] >= 0.0 { zhi } else { zlo };
        // A margin of 1e-3 of the box size keeps rounding from culling a touching box.
        pl[0] * x + pl[1] * y + pl[2] * z + pl[3] < -1e-3 * (span as f32 * p.spacing)
    })
}

/// The reference selection: the same decisions as the GPU's refine passes, without capacity
/// limits. Returns the final (drawn) tiles.
pub fn select_tiles(levels: &Levels, p: &SelectionParams) -> Vec<Tile> {
    let mut out = Vec::new();
    let mut layer = vec![Tile {
        x: 0,
        y: 0,
        lod: levels.root_lod,
    }];
    while !layer.is_empty() {
        let mut next = Vec::new();
        for t in layer {
            if !levels.inside(t) || (p.cull && tile_culled(levels, p, t)) {
                continue;
            }
            if t.lod > 0 && tile_distance(levels, p, t) < p.split[t.lod as usize] {
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    next.push(Tile {
                        x: t.x * 2 + dx,
                        y: t.y * 2 + dy,
                        lod: t.lod - 1,
                    });
                }
            } else {
                out.push(t);
            }
        }
        layer = next;
    }
    out
}

/// Morph factor of a vertex of a level-`lod` tile at integer sample `sample` (0 = own level,
/// 1 = fully on the parent level's grid). A pure function of the vertex's world position and
/// the tile's level, so vertices shared by tiles agree.
pub fn morph_factor(p: &SelectionParams, sample: [i32; 2], lod: u32, morph_range: f32) -> f32 {
    let rel = p.relative(sample);
    let d = Vec3::new(rel[0], rel[1], p.z_ref - p.camera_z).length();
    let parent_split = p.split[lod as usize + 1];
    (1.0 - (1.0 - d / parent_split) / morph_range).clamp(0.0, 1.0)
}

/// Where a vertex of a level-`lod` tile ends up after morphing, in samples (the CPU mirror of
/// the vertex shader; `local` is the vertex's grid position inside the tile).
pub fn morphed_position(
    levels: &Levels,
    p: &SelectionParams,
    t: Tile,
    local: [u32; 2],
    morph_range: f32,
) -> [f32; 2] {
    let step = 1u32 << t.lod;
    let span = levels.grid_size * step;
    let sample = [
        (t.x * span + local[0] * step) as i32,
        (t.y * span + local[1] * step) as i32,
    ];
    let m = morph_factor(p, sample, t.lod, morph_range);
    let hi = [levels.width as f32 - 1.0, levels.height as f32 - 1.0];
    std::array::from_fn(|i| {
        let odd = (local[i] & 1) as f32;
        let cell = sample[i] as f32 - odd * step as f32;
        (cell + (1.0 - m) * odd * step as f32).min(hi[i])
    })
}
