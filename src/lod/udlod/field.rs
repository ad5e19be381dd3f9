//! The split field: per-tile split distances derived from the screen-space error target
//! and each tile's own error, tied level to level by the crack-free chain, and the morph
//! zones; built on the CPU once per view size and uploaded. [`SplitField::at`] agrees with
//! `field_at` in `shaders/include/udlod_common.wgsl` operation for operation.

use super::levels::{Levels, QUAD, Tile};
use super::settings::{MORPH_LEVELS_ALL, UdlodSettings};
use crate::gpu_constants::{UDLOD_MAX_LEVELS, UDLOD_NO_SPLIT};

/// What a [`SplitField`] depends on besides the data: it is rebuilt when one of these changes
/// (in practice once per renderer and view size).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldKey {
    /// Focal length in pixels (`Camera::focal_px`).
    pub focal_px: f64,
    pub tau_px: f64,
    pub morph_range: f64,
    /// Levels over which a tile's vertices morph (`UdlodSettings::morph_levels`, resolved).
    pub morph_levels: u32,
    /// Largest ratio between a level's largest and a tile's split distance (1: one distance
    /// per level, the distance-only selection).
    pub field_max: f64,
    /// The share of a tile's worst-case projected error spent on `tau`
    /// ([`worst_case_share`](super::settings::worst_case_share) unless the settings override it).
    pub share: f64,
    /// How each cell is charged its morph zone's width: [`ZoneRule::Width`] for the morph the
    /// renderer draws; the others only for counting.
    pub zone_rule: ZoneRule,
}

/// How the split field charges each cell for its morph zone's width `W` (`zone_widths`).
/// The renderer's morph assumes [`ZoneRule::Width`]; the others are what-ifs that
/// `examples/udlod_budget.rs` counts (`--zone-rule`; `docs/udlod-rounds.md`, "What sets the field"):
/// fields built with them are not sound for the morph drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ZoneRule {
    /// The zone is `max(W, r s)` wide and charged in full (the renderer's).
    #[default]
    Width,
    /// As if the zone were `W min(1, E / s)` wide, `E` the larger of the cell's and its
    /// children's pixel terms: a zone that narrows with the error.
    ErrorScaled,
    /// As if the zone cost nothing: what `W` costs at most.
    Free,
}

impl FieldKey {
    pub fn new(settings: &UdlodSettings, focal_px: f64) -> Self {
        FieldKey {
            focal_px,
            tau_px: settings.tau_px,
            morph_range: settings.morph_range,
            morph_levels: settings.morph_levels(),
            field_max: settings.error_field_max,
            share: settings.worst_case_share(),
            zone_rule: ZoneRule::Width,
        }
    }
}

/// Relative margin on the split field's nesting and reach terms: covers the f32 rounding of
/// `m`, `D` and the `m * d < D` test on the GPU (~1e-7 each).
pub(super) const CHAIN_MARGIN: f64 = 1e-5;

/// Per-tile split distances: how near the LOD viewer may come to each tile before it splits,
/// derived per tile from its own geometric error and the pixel target, and tied between
/// levels tile by tile so the morph cascade closes every edge (`docs/udlod.md`, "Split field"
/// and "The morph cascade").
///
/// Stored as the GPU reads it: per level a split distance `D[l]` (the level's largest) and a
/// field `m_l >= 1` at the corners of the level's tiles (with `field_density` `d > 1` at the
/// corners of its field cells, `d` per tile side), interpolated bilinearly; a point's
/// split distance is `s_l(p) = D[l] / m_l(p)`. A tile splits when its nearest point (at the
/// reference height) is nearer than the largest `s` of its corners (`m_min * d < D`);
/// grid points of level `l - 1` morph over the last `morph_range` of `s_l(p)`. With `s_Q` the
/// smallest and `S_Q` the largest corner value of tile `Q`, for every tile `Q` of level `l`
/// (`cell_requirement`, per field cell; with one node per tile corner the cells are the tiles):
/// 1. pixel target: `s_Q >= k e_Q f / tau` (`e_Q`: the tile's own error, `k`:
///    [`worst_case_share`](super::settings::worst_case_share) of the grid size), so wherever `Q`'s geometry is drawn, unmorphed
///    or blended into its children's morph zone, it is at least that far away (with the morph
///    cascade `s_Q >= (1 - r) k e_Q f / tau + W[l]` too: its zone is at least `W[l]` wide);
/// 2. nesting: `s_Q >= S_P` for each child `P`: where an unsplit tile meets finer ones, their
///    edge vertices are fully morphed through every level between;
/// 3. reach: the morph zone of `s_Q` (`r s_Q`, with the morph cascade at least
///    [`Self::zone`]) starts beyond `S_G + diagonal(l - q)` for each descendant `G` of level
///    `l - q` (`q`: `FieldKey::morph_levels`; the diagonal in the LOD metric,
///    [`Levels::tile_diagonal`], `sqrt(2) extent` on square grids): a tile's vertices morph
///    over at most `q` levels and stay inside it; with walks past the tile (the default) the
///    separation instead, beyond `S_G` of level `l - 2`: no fold (`cell_requirement`);
/// 4. with the morph cascade, a gentle morph: a corner's distance is at least its neighbour's
///    over `FIELD_STEP_RATIO` (`gentle_morph`).
///
/// Level 0 never splits. Each corner takes the largest requirement of the tiles around it;
/// `field_max` then raises small values to the level's largest / `field_max`.
#[derive(Clone, Debug)]
pub struct SplitField {
    pub key: FieldKey,
    /// `D[l]` in metres: the largest split distance of each level (0 for level 0, which never
    /// splits; [`UDLOD_NO_SPLIT`] past the root), `UDLOD_MAX_LEVELS` entries as uploaded.
    pub split: Vec<f32>,
    /// Per level, the least width in metres of the zone over which the level below morphs
    /// onto it (`W[l]`; 0 with one level step, where the zone is `morph_range` of the split
    /// distance): with the morph cascade the zone is the larger of `W[l]` and `r s`
    /// (`zone_widths`). `UDLOD_MAX_LEVELS` entries as uploaded.
    pub zone: Vec<f32>,
    /// Field values `m >= 1` at every level's tile corners, `(nx + 1) x (ny + 1)` row-major
    /// per level from level 1 (level 0's are all ones and not stored).
    pub corners: Vec<f32>,
    /// Offset of each level's corners in `corners`.
    pub corner_offsets: Vec<u32>,
    /// Per level, `(k, s)` pairs: with the level's split distances ([`Self::tile_split`])
    /// sorted in decreasing order, `s` (metres) is the one at rank `k`, so `k` tiles have one of
    /// at least `s` and every other tile one of at most `s`; at `k` = 0, 1, 2, 4, 8, ... and
    /// the level's tile count (`s` = 0). What [`super::select::reserved_leaves_bound`] needs of the field,
    /// without a pass over the tiles per frame. Empty for level 0, which never splits.
    pub split_ranks: Vec<Vec<(u32, f32)>>,
}

impl SplitField {
    /// The field for `key` from `levels`, which must hold their field cells' errors
    /// ([`Levels::holds_field_errors`]; a renderer restores them before a new key).
    pub fn new(levels: &Levels, key: FieldKey) -> Self {
        assert!(
            levels.holds_field_errors(),
            "SplitField::new: the levels' field cell errors were released"
        );
        let cap = key.field_max.max(1.0);
        let zone = zone_widths(levels, &key);
        let mut field = SplitField {
            key,
            split: vec![UDLOD_NO_SPLIT; UDLOD_MAX_LEVELS as usize],
            zone,
            // Every level's nodes, allocated once (the field is the largest array UDLOD
            // builds); the levels below are read from them as the GPU evaluates them.
            corners: Vec::with_capacity(levels.field_nodes()),
            corner_offsets: Vec::new(),
            split_ranks: Vec::new(),
        };
        for lod in 0..=levels.root_lod {
            field.corner_offsets.push(field.corners.len() as u32);
            if lod == 0 {
                // Level 0 never splits: its field is 1 everywhere and not stored.
                field.split[0] = 0.0;
                continue;
            }
            field.build_level(levels, lod, cap);
        }
        field.split_ranks = (0..=levels.root_lod)
            .map(|lod| match lod {
                0 => Vec::new(),
                _ => field.ranks_of_level(levels, lod),
            })
            .collect();
        field
    }

    /// Builds level `lod`'s nodes (the levels below built): each node's split distance `s`,
    /// the largest requirement of the cells around it ([`cell_requirement`]), the gentle morph
    /// with the cascade, then its field value `D / s` clamped to `[1, cap]`.
    fn build_level(&mut self, levels: &Levels, lod: u32, cap: f64) {
        let (nx, ny) = levels.field_cells_per_side(lod);
        let cw = nx as usize + 1;
        // The level's nodes hold their split distances `s` first (f32: the chain's margin
        // covers the rounding), then their field values: no second array of the level.
        let offset = self.corners.len();
        self.corners.resize(offset + cw * (ny as usize + 1), 0.0);
        for cy in 0..ny {
            for cx in 0..nx {
                let need = cell_requirement(levels, self, [cx, cy, lod]) as f32;
                for (i, j) in QUAD {
                    let s = &mut self.corners[offset + (cy + j) as usize * cw + (cx + i) as usize];
                    *s = s.max(need);
                }
            }
        }
        let s = &mut self.corners[offset..];
        if self.key.morph_levels > 1 {
            gentle_morph(levels, lod, s);
        }
        // A level whose tiles need nothing (flat data) keeps a tiny positive distance.
        let largest = s
            .iter()
            .map(|&v| v as f64)
            .fold(1e-3 * levels.spacing, f64::max) as f32;
        self.split[lod as usize] = largest;
        let floor = largest as f64 / cap;
        for v in s {
            *v = ((largest as f64 / (*v as f64).max(floor)) as f32).clamp(1.0, cap as f32);
        }
    }

    /// The `(k, s)` pairs of [`Self::split_ranks`] for one level.
    fn ranks_of_level(&self, levels: &Levels, lod: u32) -> Vec<(u32, f32)> {
        let (nx, ny) = levels.tiles_per_side[lod as usize];
        let mut splits: Vec<f32> = (0..ny)
            .flat_map(|y| (0..nx).map(move |x| Tile { x, y, lod }))
            .map(|t| self.tile_split(levels, t) as f32)
            .collect();
        splits.sort_by(|a, b| b.total_cmp(a));
        let n = splits.len();
        let mut ranks: Vec<(u32, f32)> =
            std::iter::successors(Some(0usize), |k| Some((2 * k).max(1)))
                .take_while(|&k| k < n)
                .map(|k| (k as u32, splits[k]))
                .collect();
        ranks.push((n as u32, 0.0));
        ranks
    }

    fn corner(&self, levels: &Levels, lod: u32, i: u32, j: u32) -> f32 {
        if lod == 0 {
            return 1.0;
        }
        let (nx, _) = levels.field_cells_per_side(lod);
        self.corners[(self.corner_offsets[lod as usize] + j * (nx + 1) + i) as usize]
    }

    /// (min, max) of the field over a tile: its `(field_density + 1)^2` nodes (mirrors
    /// `tile_field_min` in `udlod_common.wgsl`).
    pub fn tile_range(&self, levels: &Levels, t: Tile) -> [f32; 2] {
        let d = levels.field_density;
        let mut range = [f32::INFINITY, f32::NEG_INFINITY];
        for j in 0..=d {
            for i in 0..=d {
                let c = self.corner(levels, t.lod, t.x * d + i, t.y * d + j);
                range = [range[0].min(c), range[1].max(c)];
            }
        }
        range
    }

    /// A tile's split distance: the largest of its corners' (`D / m_min`).
    pub fn tile_split(&self, levels: &Levels, t: Tile) -> f64 {
        self.split[t.lod as usize] as f64 / self.tile_range(levels, t)[0] as f64
    }

    /// The largest split distance, as the GPU evaluates it (`D / m` at the nodes), of the
    /// field cells of level `lod` (below `cl`, built) under field cell `[cx, cy, cl]`: `D`
    /// over the least node of their `(2^(cl - lod) + 1)^2` nodes. 0 at level 0, which never
    /// splits.
    fn largest_below(&self, levels: &Levels, [cx, cy, cl]: [u32; 3], lod: u32) -> f64 {
        let k = cl - lod;
        let (nx, ny) = levels.field_cells_per_side(lod);
        let (x0, y0) = (cx << k, cy << k);
        if lod == 0 || x0 >= nx || y0 >= ny {
            return 0.0;
        }
        let (x1, y1) = (((cx + 1) << k).min(nx), ((cy + 1) << k).min(ny));
        let least = (y0..=y1)
            .flat_map(|j| (x0..=x1).map(move |i| (i, j)))
            .map(|(i, j)| self.corner(levels, lod, i, j))
            .fold(f32::INFINITY, f32::min);
        self.split[lod as usize] as f64 / least as f64
    }

    /// The field of level `lod` at integer sample `sample` (mirrors `field_at` in
    /// `udlod_common.wgsl`): bilinear in the level's tile cell, clamped to the cell's corner
    /// range so rounding never leaves it; 1 past the root level.
    pub fn at(&self, levels: &Levels, sample: [i32; 2], lod: u32) -> f32 {
        if lod > levels.root_lod {
            return 1.0;
        }
        let ([i, j], f) = field_cell_of(levels, sample, lod);
        bilinear_in_range(QUAD.map(|(a, b)| self.corner(levels, lod, i + a, j + b)), f)
    }
}

/// The field cell of level `lod` holding integer sample `sample` (clamped to the level's
/// cells) and the sample's fraction across it.
pub(super) fn field_cell_of(levels: &Levels, sample: [i32; 2], lod: u32) -> ([u32; 2], [f32; 2]) {
    let span = (levels.field_cell_quads() << lod) as i32;
    let (nx, ny) = levels.field_cells_per_side(lod);
    let cx = (sample[0] / span).clamp(0, nx as i32 - 1);
    let cy = (sample[1] / span).clamp(0, ny as i32 - 1);
    let fx = (sample[0] - cx * span) as f32 / span as f32;
    let fy = (sample[1] - cy * span) as f32 / span as f32;
    ([cx as u32, cy as u32], [fx, fy])
}

/// Bilinear in a cell's corners `c` (ordered as [`QUAD`]) at fraction `f`, clamped to the
/// corners' range so rounding never leaves it.
pub(super) fn bilinear_in_range(c: [f32; 4], [fx, fy]: [f32; 2]) -> f32 {
    let south = c[0] * (1.0 - fx) + c[1] * fx;
    let north = c[2] * (1.0 - fx) + c[3] * fx;
    let v = south * (1.0 - fy) + north * fy;
    v.clamp(
        c[0].min(c[1]).min(c[2].min(c[3])),
        c[0].max(c[1]).max(c[2].max(c[3])),
    )
}

/// The smallest split distance field cell `[x, y, level]` (level >= 1; the tile with one
/// node per tile corner) allows at its corners, in the terms below (`field`: the field built
/// up to the level below, whose cells' split distances it reads as the GPU evaluates them):
/// - its own error at the pixel target;
/// - nesting: no less than any child's, so a point's split distance never falls from one level
///   to the next and an unsplit tile's neighbours are fully morphed onto it through every level
///   between (`docs/udlod-rounds.md`, "The morph cascade");
/// - reach: with `q` = `key.morph_levels` (at most [`cascade_levels`]), every point of a
///   descendant `G` of level `l - q` that splits is nearer than `S_G + diagonal(l - q)`, and
///   this tile's morph zone (`zone`) starts beyond that, so the vertices of `G`'s
///   children never morph at level `l - 1`: a level-`a` tile's vertices move at levels `a` to
///   `a + q - 1` only, which keeps them inside the tile (its culling box stays true), and
///   neighbours differ by at most `q` levels. With `q = 1` this is the CDLOD-style chain
///   UDLOD had before the cascade (`(1 - r) s_Q >= S_P + diagonal(l - 1)` over the children);
/// - or, with walks past the tile (`morph_levels = 0`, [`MORPH_LEVELS_ALL`]), separation: this
///   tile's morph zone starts beyond `S_G` of every descendant `G` of level `l - 2`
///   ([`SEPARATION_LEVELS`]), no diagonal: wherever level `l - 1` morphs, level `l - 3` has
///   morphed fully, so at most two successive levels morph at a point and no walk folds
///   (`docs/udlod-rounds.md`, "Walks past the tile"). Vertices then leave their tile; culling boxes
///   grow with them ([`tile_reach`]).
fn cell_requirement(levels: &Levels, field: &SplitField, cell: [u32; 3]) -> f64 {
    cell_terms(levels, field, cell).requirement()
}

/// The terms of [`cell_requirement`], each a split distance in metres.
#[derive(Clone, Copy, Debug)]
pub(super) struct CellTerms {
    /// The cell's own error at the pixel target.
    pub(super) pixel: f64,
    /// Where its morph zone `W` wide may start ([`zone_start`]) plus `W`.
    pub(super) zone: f64,
    nesting: f64,
    /// The reach over `q` levels, or with walks past the tile the separation over two.
    pub(super) separation: f64,
}

impl CellTerms {
    fn requirement(&self) -> f64 {
        let chain = self.nesting.max(self.separation) * (1.0 + CHAIN_MARGIN);
        self.pixel.max(self.zone).max(chain)
    }

    /// The term that sets the requirement (ties go to the earlier of pixel, zone, nesting).
    fn setting(&self) -> FieldTerm {
        let r = self.requirement();
        if r == self.pixel {
            FieldTerm::Pixel
        } else if r == self.zone {
            FieldTerm::Zone
        } else if self.nesting >= self.separation {
            FieldTerm::Nesting
        } else {
            FieldTerm::Separation
        }
    }
}

pub(super) fn cell_terms(
    levels: &Levels,
    field: &SplitField,
    [cx, cy, lod]: [u32; 3],
) -> CellTerms {
    let (key, zone) = (&field.key, &field.zone);
    let pixel = key.share * levels.field_cell_error(lod, cx, cy) as f64 * key.focal_px / key.tau_px;
    // This tile's geometry shows, blended, from the start of its morph zone on; where the zone
    // is `W` wide it starts no nearer than what the children's own geometry allows.
    let start = zone_start(levels, key, [cx, cy, lod], pixel);
    // The least `s` whose zone starts at or beyond `b`: `s - width >= b`.
    let w = zone[lod as usize] as f64;
    let past = |b: f64| match key.zone_rule {
        ZoneRule::Width => b + w,
        ZoneRule::ErrorScaled => {
            // `s - W E / s >= b` where `E < s`: `s^2 - b s - W E >= 0`.
            let e = pixel.max(children_pixel(levels, key, [cx, cy, lod]));
            (b + w).min((b + (b * b + 4.0 * w * e).sqrt()) / 2.0)
        }
        ZoneRule::Free => b,
    };
    let nesting = field.largest_below(levels, [cx, cy, lod], lod - 1);
    let (back, diagonal) = match key.morph_levels {
        MORPH_LEVELS_ALL => (SEPARATION_LEVELS, false),
        q => (q, true),
    };
    let separation = match lod.checked_sub(back) {
        Some(level) if level >= 1 => {
            // Where the zone is `max(W, r s)`: `s - max(W, r s) >= beyond`. The tiles of
            // level `lod - back` under a field cell are its cells of that level, whole.
            let mut beyond = field.largest_below(levels, [cx, cy, lod], level);
            if diagonal {
                beyond += levels.tile_diagonal(level);
            }
            (beyond / (1.0 - key.morph_range)).max(past(beyond))
        }
        _ => 0.0,
    };
    CellTerms {
        pixel,
        zone: past(start),
        nesting,
        separation,
    }
}

/// A term of the split field's requirement per cell (`cell_requirement`): the pixel target,
/// the morph zone's width past its start, nesting, and the reach (bounded walks) or separation.
/// Its discriminant indexes [`FieldTermCounts::cells`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldTerm {
    Pixel,
    Zone,
    Nesting,
    Separation,
}

impl FieldTerm {
    pub const ALL: [FieldTerm; 4] = [Self::Pixel, Self::Zone, Self::Nesting, Self::Separation];

    pub fn name(self) -> &'static str {
        match self {
            Self::Pixel => "pixel",
            Self::Zone => "zone",
            Self::Nesting => "nesting",
            Self::Separation => "separation",
        }
    }
}

/// Per level of `field` (index = level, 0 empty): how many field cells each [`FieldTerm`]
/// sets (indexed as [`FieldTerm::ALL`]), and how many of the level's corners the gentle
/// morph or the field's cap raised above every adjacent cell's requirement. Where the
/// triangles go at large tau (`examples/udlod_budget.rs`; `docs/udlod-rounds.md`, "What sets the
/// field").
pub fn field_terms(levels: &Levels, field: &SplitField) -> Vec<FieldTermCounts> {
    let mut out = vec![FieldTermCounts::default(); levels.root_lod as usize + 1];
    for lod in 1..=levels.root_lod {
        let (nx, ny) = levels.field_cells_per_side(lod);
        let cw = nx as usize + 1;
        let mut corner_need = vec![0.0f64; cw * (ny as usize + 1)];
        let counts = &mut out[lod as usize];
        for (cx, cy) in (0..ny).flat_map(|y| (0..nx).map(move |x| (x, y))) {
            let terms = cell_terms(levels, field, [cx, cy, lod]);
            counts.cells[terms.setting() as usize] += 1;
            for (i, j) in QUAD {
                let c = &mut corner_need[(cy + j) as usize * cw + (cx + i) as usize];
                *c = c.max(terms.requirement());
            }
        }
        for (k, need) in corner_need.iter().enumerate() {
            let (i, j) = ((k % cw) as u32, (k / cw) as u32);
            let s = field.split[lod as usize] as f64 / field.corner(levels, lod, i, j) as f64;
            counts.corners += 1;
            // f32 storage and the division: a relative 1e-5 is rounding, not a raise.
            counts.corners_raised += (s > *need * (1.0 + 1e-5) + 1e-6) as u32;
        }
    }
    out
}

/// One level's line of [`field_terms`].
#[derive(Clone, Copy, Debug, Default)]
pub struct FieldTermCounts {
    pub cells: [u32; 4],
    pub corners: u32,
    pub corners_raised: u32,
}

/// The nearest distance at which a morph zone `W` wide of field cell `[cx, cy, lod]` may
/// start, given its pixel term `screen`. In the zone the cell's children's vertices slide onto
/// its grid, so the surface there is a blend `(1 - f) children + f cell` whose error is at
/// most `(1 - f) e_c + f e` (`e_c`: the children's largest error), linear in the distance as
/// `f` and the pixel target `tau d / (k focal)` are. It meets the target at the zone's end
/// (`f = 1`, `s >= screen`) and at its start (`f = 0`) where that start is no nearer than the
/// children's own pixel term: between, too. The children's term is taken where it is the
/// nearer start; elsewhere (a child nearly as rough as the cell) `(1 - r) screen`, where one
/// level step starts its zone, which the share was measured with (`docs/udlod-rounds.md`, "The zone's
/// start", issue 18's fourteenth round). Level 1's children are level 0's: no error.
fn zone_start(levels: &Levels, key: &FieldKey, [cx, cy, lod]: [u32; 3], screen: f64) -> f64 {
    if lod < 2 {
        return 0.0;
    }
    let one_step = (1.0 - key.morph_range) * screen;
    one_step.min(children_pixel(levels, key, [cx, cy, lod]))
}

/// The largest pixel term of field cell `[cx, cy, lod]`'s children (level `lod - 1`; 0 for
/// level 1, whose children are level 0's exact samples).
fn children_pixel(levels: &Levels, key: &FieldKey, [cx, cy, lod]: [u32; 3]) -> f64 {
    if lod < 2 {
        return 0.0;
    }
    let (nx, ny) = levels.field_cells_per_side(lod - 1);
    let children = QUAD
        .iter()
        .map(|&(i, j)| (2 * cx + i, 2 * cy + j))
        .filter(|&(x, y)| x < nx && y < ny)
        .map(|(x, y)| levels.field_cell_error(lod - 1, x, y) as f64)
        .fold(0.0, f64::max);
    key.share * children * key.focal_px / key.tau_px
}

/// Levels below a tile whose split distances its morph zone starts beyond, with walks past
/// the tile ([`cell_requirement`]'s separation). A vertex odd at level `i` next to a corner
/// sliding at level `i + 2` stays on its side of it only if `1 + f_i + 2 f_i f_(i+1) >=
/// 4 f_(i+2)`: with equal split distances at the three levels and zones doubling per level
/// that fails everywhere in the zone (a fold); with level `i` fully morphed wherever `i + 2`
/// moves it reduces to `f_(i+1) >= 2 f_(i+2) - 1`, which zones doubling per level give.
const SEPARATION_LEVELS: u32 = 2;

/// Growth of the split distance allowed from one field corner to the next (8-neighbourhood):
/// see [`gentle_morph`]. 2; with 1.5 (until issue 18's fifth round) the cascade drew 0-7 %
/// more triangles on the data sets and 12-16 % more on half-rough terrain, with no fold under
/// either ratio in the fold runs (docs/udlod-rounds.md, "The morph cascade").
const FIELD_STEP_RATIO: f64 = 2.0;

/// Grid steps of the level below that the morph zone spans at least, with the morph cascade.
const ZONE_STEPS: f64 = 4.0;

/// `W[l]` per level ([`SplitField::zone`]): with the morph cascade [`ZONE_STEPS`] grid steps
/// (quad diagonals) of level `l - 1`, so the morph factor changes by at most `1 / ZONE_STEPS`
/// per step from the distance; 0 with one level step.
fn zone_widths(levels: &Levels, key: &FieldKey) -> Vec<f32> {
    let mut zone = vec![0.0f32; UDLOD_MAX_LEVELS as usize];
    if key.morph_levels > 1 {
        for lod in 1..=levels.root_lod {
            let step = levels.tile_diagonal(lod - 1) / levels.grid_size as f64;
            zone[lod as usize] = (ZONE_STEPS * step) as f32;
        }
    }
    zone
}

/// Keeps the morph of level `lod - 1`'s grid points gentle across the grid (`docs/udlod.md`,
/// "The morph cascade"): where the morph factor jumps from 0 to 1 between neighbouring
/// vertices, their triangles fold over (single pixels far off the surface, measured on
/// SRTM1). The distance's share of that is bounded by the zone's least width
/// ([`zone_widths`]); the field's by this floor on the corner split distances `s` of level
/// `lod`: a corner's distance is at least its neighbour's over [`FIELD_STEP_RATIO`] (a
/// chamfer pass each way: the largest `s(c') / ratio^steps(c, c')`), so over a tile's
/// `2 grid_size` steps of the level below the zone's end moves by at most
/// `(ratio - 1) s` against a zone of at least `r s`: with the distance's `1 / ZONE_STEPS`,
/// at most `0.25 + 1 / (2 grid_size r)` (0.875 at grid 4) per step, under the full slide.
/// Applied only with `morph_levels > 1`, so one level step keeps the selection it had.
pub(super) fn gentle_morph(levels: &Levels, lod: u32, s: &mut [f32]) {
    let (nx, ny) = levels.field_cells_per_side(lod);
    // The same growth per grid step wherever the nodes are: `d` nodes per tile side share
    // the tile's growth.
    let ratio = 1.0 + (FIELD_STEP_RATIO - 1.0) / levels.field_density as f64;
    let (w, h) = (nx as usize + 1, ny as usize + 1);
    let pass = |s: &mut [f32], order: &mut dyn Iterator<Item = usize>, back: bool| {
        for k in order {
            let (x, y) = ((k % w) as i64, (k / w) as i64);
            let dy = if back { 1 } else { -1 };
            for (ox, oy) in [(-1, 0), (1, 0), (-1, dy), (0, dy), (1, dy)] {
                let (sx, sy) = (x + ox, y + oy);
                let visited_row = oy != 0 || (if back { ox > 0 } else { ox < 0 });
                if visited_row && sx >= 0 && sy >= 0 && (sx as usize) < w && (sy as usize) < h {
                    let n = (s[sy as usize * w + sx as usize] as f64 / ratio) as f32;
                    if n > s[k] {
                        s[k] = n;
                    }
                }
            }
        }
    };
    pass(s, &mut (0..w * h), false);
    pass(s, &mut (0..w * h).rev(), true);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lod::udlod::levels::test_terrain;

    /// Every field cell's morph zone (the last `max(W, r s)` of its split distance `s`) starts
    /// no nearer than its children's pixel term or one level step's start, whichever is
    /// nearer ([`super::zone_start`]: what keeps the blended surface in the zone within
    /// tau), at one and two nodes per tile side, tau 1 and 4; and some cells start nearer
    /// than one level step's start alone allowed (the rule before issue 18's fourteenth round:
    /// `s >= (1 - r) screen + W`). Negative control by hand: a zone start of 0 fails the first.
    #[test]
    fn morph_zones_start_where_the_children_meet_tau() {
        let data = test_terrain();
        for density in [1, 2] {
            let settings = UdlodSettings {
                field_density: density,
                ..UdlodSettings::default()
            };
            let levels = Levels::for_settings(&data, &settings).unwrap();
            for tau_px in [1.0, 4.0] {
                let key = FieldKey::new(&UdlodSettings { tau_px, ..settings }, 311.8);
                let field = SplitField::new(&levels, key);
                let pixel = |lod: u32, x: u32, y: u32| {
                    let (nx, ny) = levels.field_cells_per_side(lod);
                    let e = if x < nx && y < ny && lod > 0 {
                        levels.field_cell_error(lod, x, y) as f64
                    } else {
                        0.0
                    };
                    key.share * e * key.focal_px / key.tau_px
                };
                let mut nearer = 0;
                for lod in 2..=levels.root_lod {
                    let w = field.zone[lod as usize] as f64;
                    let (nx, ny) = levels.field_cells_per_side(lod);
                    for (cx, cy) in (0..ny).flat_map(|y| (0..nx).map(move |x| (x, y))) {
                        let screen = pixel(lod, cx, cy);
                        let children = QUAD
                            .map(|(i, j)| pixel(lod - 1, 2 * cx + i, 2 * cy + j))
                            .into_iter()
                            .fold(0.0, f64::max);
                        let largest_m = QUAD
                            .map(|(i, j)| field.corner(&levels, lod, cx + i, cy + j))
                            .into_iter()
                            .fold(0.0f32, f32::max);
                        let s = field.split[lod as usize] as f64 / largest_m as f64;
                        let start = s - w.max(key.morph_range * s);
                        let one_step = (1.0 - key.morph_range) * screen;
                        let needed = children.min(one_step);
                        assert!(
                            start >= needed * (1.0 - 1e-5),
                            "density {density}, tau {tau_px}, level {lod}, cell ({cx}, {cy}): \
                             zone starts at {start} m, children need {children} m, one level \
                             step {one_step} m"
                        );
                        nearer += (s < (one_step + w) * (1.0 - 1e-5)) as u32;
                    }
                }
                assert!(
                    nearer > 0,
                    "density {density}, tau {tau_px}: no zone starts nearer than one level step's"
                );
            }
        }
    }

    /// `field_terms` names the term that sets each field cell: at a pixel target so fine that
    /// the pixel term dwarfs every zone the cells' own errors set most of them (the rest:
    /// nesting, where a child is rougher than its parent), zone and separation none; at one so
    /// coarse that it asks for nothing the zone `W` sets levels 1-2 and the separation every
    /// level above (over flat needs `s_l = s_(l-2) + W_l` beats nesting's `s_(l-1)`). Negative
    /// control by hand: `CellTerms::setting` without its zone branch fails the second part
    /// (level 1's 1,024 cells put on nesting).
    #[test]
    fn field_terms_name_what_sets_each_cell() {
        let data = test_terrain();
        // One node per tile corner: with two per side (the default) the separation term sets
        // one of level 3's cells even at tau 1e-3 (a rough cell beside smooth ones).
        let settings = UdlodSettings {
            field_density: 1,
            ..UdlodSettings::default()
        };
        let levels = Levels::for_settings(&data, &settings).unwrap();
        let counts = |tau_px: f64| {
            let key = FieldKey::new(
                &UdlodSettings {
                    tau_px,
                    ..settings.clone()
                },
                311.8,
            );
            field_terms(&levels, &SplitField::new(&levels, key))
        };
        let [pixel, zone, _, separation] = [0, 1, 2, 3];
        for (lod, c) in counts(1e-3).iter().enumerate().skip(1) {
            let cells: u32 = c.cells.iter().sum();
            let (nx, ny) = levels.field_cells_per_side(lod as u32);
            assert_eq!(cells, nx * ny, "level {lod}: every cell counted once");
            assert!(
                c.cells[pixel] * 2 >= cells && c.cells[zone] + c.cells[separation] == 0,
                "tau 1e-3, level {lod}: cells set by pixel/zone/nesting/separation {:?}",
                c.cells
            );
            assert!(c.corners_raised <= c.corners);
        }
        for (lod, c) in counts(1e4).iter().enumerate().skip(1) {
            let cells: u32 = c.cells.iter().sum();
            let expected = if lod <= 2 { zone } else { separation };
            assert_eq!(
                c.cells[expected], cells,
                "tau 1e4, level {lod}: cells set by pixel/zone/nesting/separation {:?}",
                c.cells
            );
        }
    }

    /// The what-if zone rules only ever lower the field: at every corner of every level the
    /// split distance with `ErrorScaled` is at most the renderer's (`Width`) and with `Free` at
    /// most `ErrorScaled`'s, and each is lower somewhere (257² test terrain, tau 4, where the
    /// zone sets most cells). Negative control by hand: `max` for `min` in `ErrorScaled`'s
    /// solution (the renderer's field again) fails the last: no corner lower.
    #[test]
    fn what_if_zone_rules_only_lower_the_field() {
        let data = test_terrain();
        let settings = UdlodSettings {
            tau_px: 4.0,
            ..UdlodSettings::default()
        };
        let levels = Levels::for_settings(&data, &settings).unwrap();
        let distances = |zone_rule| {
            let key = FieldKey {
                zone_rule,
                ..FieldKey::new(&settings, 311.8)
            };
            let field = SplitField::new(&levels, key);
            let mut out = Vec::new();
            for lod in 1..=levels.root_lod {
                let (nx, ny) = levels.field_cells_per_side(lod);
                for (i, j) in (0..=ny).flat_map(|j| (0..=nx).map(move |i| (i, j))) {
                    let corner = field.corner(&levels, lod, i, j) as f64;
                    out.push(field.split[lod as usize] as f64 / corner);
                }
            }
            out
        };
        let width = distances(ZoneRule::Width);
        let scaled = distances(ZoneRule::ErrorScaled);
        let free = distances(ZoneRule::Free);
        let (mut lower_scaled, mut lower_free) = (0, 0);
        for ((w, e), f) in width.iter().zip(&scaled).zip(&free) {
            assert!(
                *e <= w * (1.0 + 1e-5),
                "error-scaled {e} m above width's {w} m"
            );
            assert!(
                *f <= e * (1.0 + 1e-5),
                "free {f} m above error-scaled {e} m"
            );
            lower_scaled += (*e < w * 0.99) as u32;
            lower_free += (*f < e * 0.99) as u32;
        }
        assert!(
            lower_scaled > 0 && lower_free > 0,
            "{lower_scaled} / {lower_free} corners lower"
        );
    }

    /// Released field cell errors come back bit for bit from the same statistics read again
    /// (the renderer's path for a new field key): the field built after the restore equals the
    /// one built before. Controls: released, the levels cannot build a field; another grid's
    /// cells are refused with a one-line error naming the nodes per tile side.
    #[test]
    fn released_field_errors_come_back_bit_for_bit() {
        let data = test_terrain();
        let settings = UdlodSettings::default();
        let d = settings.field_density();
        assert!(d > 1);
        let cells = |grid: u32| {
            let stats = crate::dataset::stats::TileStats::compute_serial(&data, grid).unwrap();
            crate::dataset::stats::FieldStats::from_cells(stats, d).unwrap()
        };
        let mut levels = Levels::from_field_stats(cells(settings.grid_size / d), data.spacing);
        let key = FieldKey::new(&settings, 311.8);
        let before = SplitField::new(&levels, key);
        levels.release_field_errors();
        assert!(!levels.holds_field_errors() && levels.field_error.is_empty());
        assert!(std::panic::catch_unwind(|| SplitField::new(&levels, key)).is_err());
        let wrong = levels
            .restore_field_errors(cells(settings.grid_size))
            .unwrap_err();
        assert!(
            wrong
                .to_string()
                .contains(&format!("({d} nodes per tile side)")),
            "{wrong}"
        );
        assert!(!levels.holds_field_errors());
        levels
            .restore_field_errors(cells(settings.grid_size / d))
            .unwrap();
        assert!(levels.holds_field_errors());
        let after = SplitField::new(&levels, key);
        assert_eq!(
            (before.split, before.zone, before.corners),
            (after.split, after.zone, after.corners)
        );
    }
}
