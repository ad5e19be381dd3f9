//! The vertex morph cascade on the CPU: morph factors, the walks past the tile, the collapse
//! masks and the morphed vertex, in f32 in the same order as
//! `shaders/include/udlod_morph.wgsl` (tests compare the GPU's vertices with these).

use glam::Vec3;

use super::levels::{Levels, Tile};
use super::params::SelectionParams;
use crate::gpu_constants::UDLOD_COLLAPSE_MARGIN;

/// One step of every morph walk: where grid point `point` slides at level `j`, its lower even
/// neighbour there (itself where it is even at `j`). `slid_at` in
/// `shaders/include/udlod_morph.wgsl`.
fn slid_at(point: [i32; 2], j: u32) -> [i32; 2] {
    point.map(|v| v - (((v as u32 >> j) & 1) as i32) * (1 << j))
}

/// The last point of grid point `sample`'s morph walk from level `lod`: [`morph_cascade`]'s
/// walk up, without the positions. Every point of the walk lies between it and `sample`.
/// `walk_on` in `shaders/include/udlod_morph.wgsl` (from the point's first odd level).
pub fn walk_end(levels: &Levels, p: &SelectionParams, sample: [i32; 2], lod: u32) -> [i32; 2] {
    let mut point = sample;
    for j in lod..levels.root_lod {
        let odd = point.map(|v| ((v as u32 >> j) & 1) as i32);
        if odd == [0, 0] {
            continue;
        }
        if !morph_moves(levels, p, point, j) {
            break;
        }
        point = slid_at(point, j);
    }
    point
}

/// Whether [`morph_factor`] is not 0, without the fold's neighbour reads: the fold only lowers
/// a factor above 1/2 to one of at least 1/2, so the factor is 0 exactly where the ramp is not
/// above 0 or morphing is off. What the walks ask (`morph_moves` in
/// `shaders/include/udlod_morph.wgsl`; on Mesa 22.3, which runs every branch, the fold's
/// reads were two more ramps in each of the prepass's walk steps).
pub fn morph_moves(levels: &Levels, p: &SelectionParams, sample: [i32; 2], lod: u32) -> bool {
    p.morph && morph_ramp(levels, p, sample, lod) > 0.0
}

/// Morph factor of grid point `sample` of level `lod` (0 = its own level's grid, 1 = fully on
/// the next level's grid; 0 everywhere with morphing off): the next level's scaled distance
/// against the last `morph_range` of its split distance, or with the morph cascade the last
/// `max(zone, morph_range s)` metres of the point's split distance `s`
/// ([`super::field::SplitField::zone`]). A pure function of the point and the
/// level, so vertices shared by tiles agree. `morph_factor` in
/// `shaders/include/udlod_morph.wgsl`, operation for operation.
pub fn morph_factor(levels: &Levels, p: &SelectionParams, sample: [i32; 2], lod: u32) -> f32 {
    let on = if p.morph { 1.0 } else { 0.0 };
    let mut f = morph_ramp(levels, p, sample, lod).clamp(0.0, 1.0);
    // A point odd along both axes stays within `(1 + b) / 2`, `b` the smaller factor of its
    // neighbours at (1, 0) and (0, 1) of its block, or the triangle between the three turns
    // over (docs/udlod-rounds.md, "Folds at the quads' diagonal"). (The shader reads the two
    // neighbours in a loop from a least factor of 1: the same minimum of values in [0, 1].)
    if f > 0.5 && sample.map(|v| (v as u32 >> lod) & 1) == [1, 1] {
        let step = 1 << lod;
        let along_x = morph_ramp(levels, p, [sample[0], sample[1] - step], lod).clamp(0.0, 1.0);
        let along_y = morph_ramp(levels, p, [sample[0] - step, sample[1]], lod).clamp(0.0, 1.0);
        f = f.min(0.5 * (1.0 + along_x.min(along_y)));
    }
    f * on
}

/// [`morph_factor`] before its clamp to `[0, 1]` and the on/off switch (`morph_ramp` in
/// `shaders/include/udlod_morph.wgsl`): at least 1 where the point lies fully on the next
/// level's grid.
fn morph_ramp(levels: &Levels, p: &SelectionParams, sample: [i32; 2], lod: u32) -> f32 {
    let d = viewer_distance(p, sample);
    let field = p.field.at(levels, sample, lod + 1);
    let parent_split = p.field.split[lod as usize + 1];
    let zone = p.field.zone[lod as usize + 1];
    if zone > 0.0 {
        return cascade_ramp(p, d, parent_split / field, zone);
    }
    let scaled = d * field;
    1.0 - (1.0 - scaled / parent_split) / p.morph_range
}

/// The LOD viewer's distance to integer sample `sample` in the LOD metric (at the reference
/// height), as the morph measures it.
pub(super) fn viewer_distance(p: &SelectionParams, sample: [i32; 2]) -> f32 {
    let rel = p.from_viewer(sample);
    Vec3::new(rel[0] * p.stretch[0], rel[1] * p.stretch[1], p.viewer[2]).length()
}

/// The morph cascade's ramp at distance `d` for a morph completing at `s` over a zone at
/// least `zone` wide: 1 at `s`, falling over the last `max(zone, morph_range s)`.
pub(super) fn cascade_ramp(p: &SelectionParams, d: f32, s: f32, zone: f32) -> f32 {
    let width = zone.max(p.morph_range * s);
    1.0 - (s - d) / width
}

/// Which quadrants of tile `t` are drawn as the parent's grid (bit `qx + 2 qy`,
/// [`super::grid`]): those whose grid vertices odd at the tile's level all lie fully on the
/// parent's grid (`final_tile_checks` in `shaders/udlod_tiling.wgsl`; `grid_size` must be
/// even). Their odd vertices coincide with even ones, so the quadrant's triangles are the
/// parent grid's over its even vertices (each parent quad's two, the same diagonal) and
/// degenerate ones (`docs/udlod-rounds.md`, "Collapsed quadrants"). At grid 2 a tile is drawn so only
/// when all four are ([`super::grid::TileMask::new`]).
pub fn tile_collapse_mask(levels: &Levels, p: &SelectionParams, t: Tile) -> u32 {
    if !p.morph {
        return 0;
    }
    collapse_mask_by(levels, t, |sample| morph_ramp(levels, p, sample, t.lod))
}

/// [`tile_collapse_mask`] with the odd vertices' morph ramp given (`ramp` of a sample).
pub(super) fn collapse_mask_by(levels: &Levels, t: Tile, ramp: impl Fn([i32; 2]) -> f32) -> u32 {
    let g = levels.grid_size;
    let mut keeps = 0;
    for j in 0..=g {
        for i in (0..=g).filter(|i| (i | j) & 1 == 1) {
            let quadrants = super::grid::quadrants_of(g, [i, j]);
            if quadrants & !keeps != 0
                && ramp(tile_sample(levels, t, [i, j])) < 1.0 + UDLOD_COLLAPSE_MARGIN
            {
                keeps |= quadrants;
            }
        }
    }
    super::grid::ALL_QUADRANTS & !keeps
}

/// How a grid point moved in [`morph_cascade`] (`MORPH_*` and `morph_moved` in
/// `shaders/include/udlod_morph.wgsl`, which the prepass's back-face split asks of every vertex).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Moved {
    /// Not at all.
    Still,
    /// Fully onto the parent grid at the tile's own level, and no further: the tile's
    /// triangles stay the parent grid's (or degenerate).
    OneLevel,
    /// Part-way, or on through further levels: sliver triangles possible (the prepass's
    /// `final_tile_checks` draws the tile without back-face culling).
    Slivers,
}

/// A grid point after the morph cascade (`Cascade` in `shaders/include/udlod_morph.wgsl`):
/// an integer cell plus a fraction, not yet folded or clamped.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cascade {
    pub cell: [i32; 2],
    pub frac: [f32; 2],
    /// The factor at the point's first odd level (0 if it reached none).
    pub morph: f32,
    /// How it moved (on the GPU its own walk, `morph_moved`).
    pub moved: Moved,
    /// Levels at which it moved (CPU only: tests count vertices morphing over several).
    pub levels: u32,
}

/// Where grid point `sample` of a level-`lod` tile ends up (`docs/udlod-rounds.md`, "The morph
/// cascade"): up, at every level `j` from `lod` on at which the point reached is odd, it has
/// the factor [`morph_factor`] there and slides towards its lower even neighbour, the next
/// point, until a factor of 0; down, the last point stays and each earlier one lies `1 - f` of
/// the way from where the next one ended up back towards itself. The CPU mirror of
/// `morph_cascade` in `shaders/include/udlod_morph.wgsl`, the same f32 and integer operations
/// in the same order.
pub fn morph_cascade(levels: &Levels, p: &SelectionParams, sample: [i32; 2], lod: u32) -> Cascade {
    let mut c = Cascade {
        cell: sample,
        frac: [0.0; 2],
        morph: 0.0,
        moved: Moved::Still,
        levels: 0,
    };
    let mut walk: Vec<([i32; 2], f32)> = Vec::new();
    let mut point = sample;
    let mut first = true;
    for j in lod..levels.root_lod {
        let odd = point.map(|v| ((v as u32 >> j) & 1) as i32);
        if odd == [0, 0] {
            continue;
        }
        let f = morph_factor(levels, p, point, j);
        if first {
            c.morph = f;
            first = false;
        }
        if f == 0.0 {
            break;
        }
        c.moved = if c.moved == Moved::Still && j == lod && f == 1.0 {
            Moved::OneLevel
        } else {
            Moved::Slivers
        };
        walk.push((point, f));
        point = slid_at(point, j);
    }
    c.levels = walk.len() as u32;
    c.cell = point;
    for &(from, f) in walk.iter().rev() {
        if f < 1.0 {
            c.frac =
                [0, 1].map(|i| c.frac[i] + (1.0 - f) * ((from[i] - c.cell[i]) as f32 - c.frac[i]));
        }
    }
    c
}

/// Integer sample of vertex `local` of tile `t`: u32 arithmetic (wrapping), then the cast, as
/// the shaders do.
fn tile_sample(levels: &Levels, t: Tile, local: [u32; 2]) -> [i32; 2] {
    let step = 1u32 << t.lod;
    let tile = [t.x, t.y];
    std::array::from_fn(|i| {
        let origin = tile[i].wrapping_mul(levels.grid_size).wrapping_mul(step);
        origin.wrapping_add(local[i].wrapping_mul(step)) as i32
    })
}

/// A tile's grid vertex after morphing (`MorphedVertex` in `shaders/include/udlod_morph.wgsl`
/// without the height): an integer sample `cell` plus a fraction in `[0, 1)` per axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MorphedVertex {
    pub cell: [i32; 2],
    pub frac: [f32; 2],
    /// The morph factor at the vertex's first odd level.
    pub morph: f32,
    /// Levels at which it moved (CPU only, [`Cascade::levels`]).
    pub levels: u32,
    /// How it moved (CPU only: tests check the prepass's back-face split against it).
    pub moved: Moved,
}

impl MorphedVertex {
    /// The position in samples as the shaders form it (`vec2<f32>(cell) + frac`).
    pub fn grid_pos(&self) -> [f32; 2] {
        [
            self.cell[0] as f32 + self.frac[0],
            self.cell[1] as f32 + self.frac[1],
        ]
    }
}

/// Where vertex `local` (column, row in the tile's grid) of tile `t` ends up after morphing:
/// the CPU mirror of `morphed_vertex` in `shaders/include/udlod_morph.wgsl`, the same f32 and
/// integer operations in the same order ([`morph_cascade`], whole samples folded from the
/// fraction into the cell, clamped at the data's last sample). `tests/udlod.rs` proves it
/// equal to the GPU's through the morph probe.
pub fn morphed_vertex(
    levels: &Levels,
    p: &SelectionParams,
    t: Tile,
    local: [u32; 2],
) -> MorphedVertex {
    let c = morph_cascade(levels, p, tile_sample(levels, t, local), t.lod);
    let last = [levels.width as i32 - 1, levels.height as i32 - 1];
    let mut cell = [0i32; 2];
    let mut frac = [0f32; 2];
    for i in 0..2 {
        let whole = c.frac[i].floor();
        let mut ce = c.cell[i] + whole as i32;
        let mut f = c.frac[i] - whole;
        f = f.min((last[i] - ce).max(0) as f32);
        ce = ce.min(last[i]);
        cell[i] = ce;
        frac[i] = f;
    }
    MorphedVertex {
        cell,
        frac,
        morph: c.morph,
        levels: c.levels,
        moved: c.moved,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lod::udlod::levels::{test_poses, test_terrain};
    use crate::lod::udlod::settings::UdlodSettings;

    /// `morph_moves` answers `morph_factor != 0` at every grid point of every level of the
    /// test terrain from four poses, with morphing on and off; and the poses reach both
    /// answers, and factors the fold lowered. Negative controls by hand: `morph_moves` without `p.morph` fails (morphing off),
    /// and with `> 0.5` for `> 0.0` (a factor of 0.4994617 at level 0).
    #[test]
    fn morph_moves_is_a_nonzero_morph_factor() {
        let data = test_terrain();
        let (mut moving, mut still, mut folds) = (0u32, 0u32, 0u32);
        for morph in [true, false] {
            let settings = UdlodSettings {
                morph,
                ..UdlodSettings::default()
            };
            let levels = Levels::for_settings(&data, &settings).unwrap();
            for (k, cam) in test_poses().iter().enumerate() {
                let p =
                    SelectionParams::new(&levels, &data, &settings, cam, cam.position, 640, 360);
                for lod in 0..levels.root_lod {
                    let step = 1usize << lod;
                    for y in (0..levels.height as i32).step_by(step) {
                        for x in (0..levels.width as i32).step_by(step) {
                            let f = morph_factor(&levels, &p, [x, y], lod);
                            let moves = morph_moves(&levels, &p, [x, y], lod);
                            assert_eq!(
                                moves,
                                f != 0.0,
                                "morph {morph}, pose {k}, level {lod}, ({x}, {y}): factor {f}"
                            );
                            moving += moves as u32;
                            still += !moves as u32;
                            let ramp = morph_ramp(&levels, &p, [x, y], lod).clamp(0.0, 1.0);
                            folds += (morph && f < ramp) as u32;
                        }
                    }
                }
            }
        }
        assert!(
            moving > 0 && still > 0 && folds > 0,
            "moving {moving}, still {still}, lowered by the fold {folds}"
        );
    }
}
