//! The clipped quadtree of one view: per level a `node_count x node_count` window of nodes
//! centred on the viewer (clamped into the level), addressed toroidally, each entry pointing at
//! the best *resident* node covering it (`{atlas_index, atlas_lod}`; the nearest resident
//! ancestor when the node itself is missing).
//!
//! [`ViewQuadtree::lookup`] is the one height formula: `shaders/include/clipmap.wgsl` performs the same f32
//! operations in the same order (power-of-two scales built from exponent bits, integer node
//! arithmetic, no division or transcendental), and `tests/clipmap.rs` reads GPU heights back
//! and proves them equal.

use glam::DVec2;

use super::atlas::Atlas;
use super::{Geometry, NodeKey};
use crate::gpu_constants::{CLIPMAP_LOD_SHIFT, CLIPMAP_MAX_LEVELS};

/// Entry of a quadtree cell that has no resident node at all (never after the root is
/// loaded, which [`super::Clipmap::new`] does before the first frame).
pub const NO_NODE: u32 = u32::MAX;

/// `2^-l` exactly, built from the exponent bits (the shader does the same).
pub fn inv_pow2(l: u32) -> f32 {
    f32::from_bits((127 - l) << 23)
}

/// `1 / center` as the f32 both sides multiply by to find a node.
pub fn inv_center(geometry: &Geometry) -> f32 {
    1.0 / geometry.center as f32
}

/// Level-`l` continuous texel coordinate of a level-0 sample position (texel centres at
/// integers; a level-`l` texel `u` covers samples `2^l u .. 2^l (u + 1) - 1`).
pub fn level_coord(p: [f32; 2], l: u32) -> [f32; 2] {
    let half = ((1u32 << l) as f32 - 1.0) * 0.5;
    let inv = inv_pow2(l);
    [(p[0] - half) * inv, (p[1] - half) * inv]
}

/// The state of one view's quadtree as the GPU reads it.
#[derive(Clone, Debug)]
pub struct ViewQuadtree {
    pub node_count: u32,
    /// Per level: window origin (nodes) and the level's node counts.
    pub levels: Vec<[i32; 4]>,
    /// `lod_count x n x n` packed entries, index `(l * n + y % n) * n + x % n`.
    pub entries: Vec<u32>,
    /// The node each cell holds (toroidal slot -> node), for tests and change tracking.
    pub keys: Vec<Option<NodeKey>>,
    /// Cells per level whose node changed in the last recentre.
    pub changed: Vec<u32>,
    /// Cells (within the data) that point at a coarser node than their own in the last frame.
    pub fallback_cells: u64,
    /// 1 / width of the band (level texels) at a window's inner edge in which the level is
    /// blended with the next coarser one; 0: no blending.
    pub blend_inv: f32,
    /// The viewer (level-0 samples, clamped into the data) of the last recentre.
    pub viewer: [f32; 2],
}

impl ViewQuadtree {
    pub fn new(geometry: &Geometry, node_count: u32, blend_nodes: f64) -> Self {
        let cells = geometry.levels.len() * (node_count * node_count) as usize;
        ViewQuadtree {
            node_count,
            levels: vec![[0; 4]; geometry.levels.len()],
            entries: vec![NO_NODE; cells],
            keys: vec![None; cells],
            changed: vec![0; geometry.levels.len()],
            fallback_cells: 0,
            viewer: [0.0; 2],
            blend_inv: if blend_nodes > 0.0 {
                (1.0 / (blend_nodes * geometry.center as f64)) as f32
            } else {
                0.0
            },
        }
    }

    fn cell(&self, l: u32, x: u32, y: u32) -> usize {
        let n = self.node_count;
        ((l * n + y % n) * n + x % n) as usize
    }

    /// Recentres every level's window on `viewer` (level-0 sample units) and returns the nodes
    /// of all windows with a priority key (smaller = sooner: coarse first, then near).
    pub fn recentre(&mut self, geometry: &Geometry, viewer: DVec2) -> Vec<(NodeKey, (u32, u64))> {
        // Outside the data the windows are those of the nearest point inside (clamping the
        // origins gives the same); the shader's level estimate relies on the clamped viewer.
        let viewer = viewer.clamp(
            DVec2::ZERO,
            DVec2::new(geometry.width as f64 - 1.0, geometry.height as f64 - 1.0),
        );
        self.viewer = [viewer.x as f32, viewer.y as f32];
        let n = self.node_count as i64;
        let c = geometry.center as f64;
        let lods = geometry.levels.len() as u32;
        let mut wanted = Vec::new();
        self.changed.iter_mut().for_each(|c| *c = 0);
        for l in 0..lods {
            let (nx, ny) = geometry.levels[l as usize];
            let half = ((1u64 << l) as f64 - 1.0) * 0.5;
            let s = (1u64 << l) as f64;
            let centre = |v: f64, nodes: u32| {
                let node = (((v - half) / s) / c).floor() as i64;
                (node - n / 2).clamp(0, (nodes as i64 - n).max(0))
            };
            let (ox, oy) = (centre(viewer.x, nx), centre(viewer.y, ny));
            self.levels[l as usize] = [ox as i32, oy as i32, nx as i32, ny as i32];
            let (vx, vy) = (
                ((viewer.x - half) / s / c).floor(),
                ((viewer.y - half) / s / c).floor(),
            );
            for y in oy..(oy + n).min(ny as i64) {
                for x in ox..(ox + n).min(nx as i64) {
                    let key = NodeKey {
                        lod: l,
                        x: x as u32,
                        y: y as u32,
                    };
                    let cell = self.cell(l, key.x, key.y);
                    if self.keys[cell] != Some(key) {
                        self.keys[cell] = Some(key);
                        self.changed[l as usize] += 1;
                    }
                    let d = (x as f64 - vx).abs().max((y as f64 - vy).abs()) as u64;
                    wanted.push((key, (lods - 1 - l, d)));
                }
            }
        }
        wanted
    }

    /// Points every cell of every window at its best resident node.
    pub fn resolve(&mut self, geometry: &Geometry, atlas: &Atlas) {
        let n = self.node_count as i32;
        let lods = geometry.levels.len() as u32;
        self.fallback_cells = 0;
        for l in 0..lods {
            let [ox, oy, nx, ny] = self.levels[l as usize];
            for y in oy..(oy + n).min(ny) {
                for x in ox..(ox + n).min(nx) {
                    let mut key = NodeKey {
                        lod: l,
                        x: x as u32,
                        y: y as u32,
                    };
                    let entry = loop {
                        if let Some(layer) = atlas.layer_of(key) {
                            break layer as u32 | key.lod << CLIPMAP_LOD_SHIFT;
                        }
                        if key.lod + 1 >= lods {
                            break NO_NODE;
                        }
                        key = key.parent();
                    };
                    if entry == NO_NODE || entry >> CLIPMAP_LOD_SHIFT != l {
                        self.fallback_cells += 1;
                    }
                    let cell = self.cell(l, x as u32, y as u32);
                    self.entries[cell] = entry;
                }
            }
        }
    }

    /// The node of level `l` containing `p` (clamped into the level's node grid).
    fn node_of(&self, geometry: &Geometry, p: [f32; 2], l: u32) -> [i32; 2] {
        let inv_c = inv_center(geometry);
        let [_, _, nx, ny] = self.levels[l as usize];
        let t = level_coord(p, l);
        [
            ((t[0] * inv_c).floor() as i32).clamp(0, nx - 1),
            ((t[1] * inv_c).floor() as i32).clamp(0, ny - 1),
        ]
    }

    fn in_window(&self, node: [i32; 2], l: u32) -> bool {
        let n = self.node_count as i32;
        let [ox, oy, nx, ny] = self.levels[l as usize];
        node[0] >= ox && node[1] >= oy && node[0] < ox + n.min(nx) && node[1] < oy + n.min(ny)
    }

    /// The quadtree level and node a position is looked up in: the finest level whose window
    /// contains the position's node (the root level always does).
    pub fn locate(&self, geometry: &Geometry, p: [f32; 2]) -> (u32, [i32; 2]) {
        let lods = geometry.levels.len() as u32;
        let mut l = 0;
        loop {
            let node = self.node_of(geometry, p, l);
            if self.in_window(node, l) || l + 1 >= lods {
                return (l, node);
            }
            l += 1;
        }
    }

    /// Bilinear height within the best resident node of cell `node` of level `l`.
    fn level_height(
        &self,
        geometry: &Geometry,
        atlas: &Atlas,
        p: [f32; 2],
        l: u32,
        node: [i32; 2],
    ) -> f32 {
        let e = self.entries[self.cell(l, node[0] as u32, node[1] as u32)];
        if e == NO_NODE {
            return 0.0;
        }
        let layer = (e & ((1 << CLIPMAP_LOD_SHIFT) - 1)) as u16;
        let al = e >> CLIPMAP_LOD_SHIFT;
        let c = geometry.center as i32;
        let b = geometry.border as i32;
        let side = c + 2 * b;
        let shift = al - l;
        let anc = [node[0] >> shift, node[1] >> shift];
        let t = level_coord(p, al);
        let local = [t[0] - (anc[0] * c) as f32, t[1] - (anc[1] * c) as f32];
        let base = [local[0].floor(), local[1].floor()];
        let f = [local[0] - base[0], local[1] - base[1]];
        let i = (base[0] as i32 + b).clamp(0, side - 2) as u32;
        let j = (base[1] as i32 + b).clamp(0, side - 2) as u32;
        let h00 = atlas.texel(layer, i, j);
        let h10 = atlas.texel(layer, i + 1, j);
        let h01 = atlas.texel(layer, i, j + 1);
        let h11 = atlas.texel(layer, i + 1, j + 1);
        let south = h00 + (h10 - h00) * f[0];
        let north = h01 + (h11 - h01) * f[0];
        south + (north - south) * f[1]
    }

    /// Height at a level-0 sample position: exactly what `clipmap_height` in
    /// `shaders/include/clipmap.wgsl` returns for the same state (level `l`, blended with level
    /// `l + 1` within the blend band of the window's inner edges).
    pub fn lookup(&self, geometry: &Geometry, atlas: &Atlas, p: [f32; 2]) -> f32 {
        let lods = geometry.levels.len() as u32;
        let (l, node) = self.locate(geometry, p);
        let h = self.level_height(geometry, atlas, p, l, node);
        if l + 1 >= lods || self.blend_inv == 0.0 {
            return h;
        }
        let c = geometry.center as i32;
        let n = self.node_count as i32;
        let [ox, oy, nx, ny] = self.levels[l as usize];
        let (wx, wy) = (n.min(nx), n.min(ny));
        let t = level_coord(p, l);
        let far = 3.0e38f32;
        let lo = [t[0] - (ox * c) as f32, t[1] - (oy * c) as f32];
        let hi = [((ox + wx) * c) as f32 - t[0], ((oy + wy) * c) as f32 - t[1]];
        let dlo = [
            if ox == 0 { far } else { lo[0] },
            if oy == 0 { far } else { lo[1] },
        ];
        let dhi = [
            if ox + wx >= nx { far } else { hi[0] },
            if oy + wy >= ny { far } else { hi[1] },
        ];
        let d = dlo[0].min(dlo[1]).min(dhi[0].min(dhi[1]));
        let weight = (d * self.blend_inv).clamp(0.0, 1.0);
        if weight >= 1.0 {
            return h;
        }
        let node1 = self.node_of(geometry, p, l + 1);
        if !self.in_window(node1, l + 1) {
            return h;
        }
        let h1 = self.level_height(geometry, atlas, p, l + 1, node1);
        h1 + (h - h1) * weight
    }

    /// The GPU form: [`ClipmapHeader`] followed by the entries (`Clipmap` in
    /// `shaders/include/clipmap.wgsl`).
    pub fn gpu_bytes(&self, geometry: &Geometry, out: &mut Vec<u8>) {
        let side = geometry.center + 2 * geometry.border;
        let mut header = ClipmapHeader {
            params: [
                1,
                geometry.levels.len() as u32,
                self.node_count,
                geometry.center,
            ],
            params2: [
                geometry.border,
                side,
                self.blend_inv.to_bits(),
                inv_center(geometry).to_bits(),
            ],
            viewer: [self.viewer[0], self.viewer[1], 0.0, 0.0],
            levels: [[0, 0, 1, 1]; CLIPMAP_MAX_LEVELS as usize],
        };
        for (dst, src) in header.levels.iter_mut().zip(&self.levels) {
            *dst = *src;
        }
        out.clear();
        out.extend_from_slice(bytemuck::bytes_of(&header));
        out.extend_from_slice(bytemuck::cast_slice(&self.entries));
    }
}

/// The header of a view's quadtree on the GPU (`Clipmap` in `shaders/include/clipmap.wgsl`,
/// the members before `entries`; a test proves the layouts equal).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ClipmapHeader {
    /// Enabled (1), levels, node count, centre texels.
    pub params: [u32; 4],
    /// Border texels, texels per layer side, f32 bits of 1 / blend band, of 1 / centre texels.
    pub params2: [u32; 4],
    /// The viewer in level-0 samples (xy).
    pub viewer: [f32; 4],
    /// Per level: window origin (nodes) xy, the level's node counts zw (unused levels 0, 0,
    /// 1, 1).
    pub levels: [[i32; 4]; CLIPMAP_MAX_LEVELS as usize],
}

/// Bytes of the GPU header before the entries.
pub const HEADER_BYTES: u64 = size_of::<ClipmapHeader>() as u64;
