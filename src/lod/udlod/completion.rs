//! What-if, counted by `examples/udlod_budget.rs` (issue 18, twenty-seventh round; the
//! renderer does not draw it): the morph completing at a distance `c` of its own, below the
//! split field `s`, so that more quadrants collapse (`docs/udlod-rounds.md`, "A completion field
//! below the split field, counted").
//!
//! Cracks and pops need only `c <= s` at every level. The fold conditions need `c` to grow
//! level by level at each point and to keep the separation; the pixel target needs the zone
//! past its start. So level `l + 1`'s morph completes at `c(p) = min(s_(l+1)(p),
//! max(r_(l+1)(p), s_l(p)))`: `r` a field of the cells' pixel, zone and separation terms
//! (each corner the largest of its cells, with the gentle morph), and `s_l(p)` in place of
//! nesting's maximum over the cell. [`CompletionTerms`] drops terms from `r` for unsound
//! bounds.

use super::field::{
    CHAIN_MARGIN, SplitField, bilinear_in_range, cell_terms, field_cell_of, gentle_morph,
};
use super::levels::{Levels, QUAD, Tile};
use super::morph::{cascade_ramp, collapse_mask_by, viewer_distance};
use super::params::SelectionParams;

/// Which of a cell's terms the completion field `r` keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CompletionTerms {
    /// Pixel, zone and separation: what the fold and pixel arguments need.
    Sound,
    /// Pixel and zone (unsound: no separation).
    PixelAndZone,
    /// The pixel term alone (unsound).
    Pixel,
}

impl CompletionTerms {
    pub const ALL: [CompletionTerms; 3] = [Self::Sound, Self::PixelAndZone, Self::Pixel];

    pub fn name(self) -> &'static str {
        match self {
            Self::Sound => "pixel, zone, separation (sound)",
            Self::PixelAndZone => "pixel and zone (unsound)",
            Self::Pixel => "pixel alone (unsound)",
        }
    }
}

/// The field `r` of completion distances (metres) at every level's field corners, laid out
/// as [`SplitField::corners`].
pub struct CompletionField {
    corners: Vec<f32>,
}

impl CompletionField {
    /// `r` for `field` (whose levels must still hold their field cells' errors).
    pub fn new(levels: &Levels, field: &SplitField, terms: CompletionTerms) -> Self {
        let mut corners = vec![0.0f32; field.corners.len()];
        for lod in 1..=levels.root_lod {
            let (nx, ny) = levels.field_cells_per_side(lod);
            let cw = nx as usize + 1;
            let offset = field.corner_offsets[lod as usize] as usize;
            let level = &mut corners[offset..offset + cw * (ny as usize + 1)];
            for (cx, cy) in (0..ny).flat_map(|y| (0..nx).map(move |x| (x, y))) {
                let t = cell_terms(levels, field, [cx, cy, lod]);
                let need = match terms {
                    CompletionTerms::Sound => {
                        t.pixel.max(t.zone).max(t.separation * (1.0 + CHAIN_MARGIN))
                    }
                    CompletionTerms::PixelAndZone => t.pixel.max(t.zone),
                    CompletionTerms::Pixel => t.pixel,
                } as f32;
                for (i, j) in QUAD {
                    let v = &mut level[(cy + j) as usize * cw + (cx + i) as usize];
                    *v = v.max(need);
                }
            }
            if field.key.morph_levels > 1 {
                gentle_morph(levels, lod, level);
            }
        }
        CompletionField { corners }
    }

    /// `r` of level `lod` (>= 1, at most the root) at integer sample `sample`.
    fn at(&self, levels: &Levels, field: &SplitField, sample: [i32; 2], lod: u32) -> f32 {
        let ([i, j], f) = field_cell_of(levels, sample, lod);
        let (nx, _) = levels.field_cells_per_side(lod);
        let offset = field.corner_offsets[lod as usize];
        bilinear_in_range(
            QUAD.map(|(a, b)| self.corners[(offset + (j + b) * (nx + 1) + i + a) as usize]),
            f,
        )
    }

    /// Where the morph of level `lod`'s odd points onto level `lod + 1` completes at `sample`.
    fn completion(&self, levels: &Levels, p: &SelectionParams, sample: [i32; 2], lod: u32) -> f32 {
        let split = |l: u32| p.field.split[l as usize] / p.field.at(levels, sample, l);
        let own = if lod == 0 { 0.0 } else { split(lod) };
        split(lod + 1).min(self.at(levels, &p.field, sample, lod + 1).max(own))
    }

    /// [`super::morph::tile_collapse_mask`] with the morph completing at this field (the
    /// morph cascade on, `morph_levels > 1`).
    pub fn tile_collapse_mask(&self, levels: &Levels, p: &SelectionParams, t: Tile) -> u32 {
        if !p.morph || t.lod >= levels.root_lod {
            return 0;
        }
        let zone = p.field.zone[t.lod as usize + 1];
        collapse_mask_by(levels, t, |sample| {
            let c = self.completion(levels, p, sample, t.lod);
            cascade_ramp(p, viewer_distance(p, sample), c, zone)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::super::{levels, morph, select};
    use super::*;
    use crate::lod::UdlodSettings;

    /// The completion lies at or before the split distance, so every quadrant today's morph
    /// collapses stays collapsed, whichever terms `r` keeps; with the pixel term alone some
    /// more collapse (on this terrain the sound field adds none, as on the CI data). Negative
    /// control, by hand: `completion` without its `min` with `split(lod + 1)` and 1.5x larger
    /// uncollapses quadrants (pose 0).
    #[test]
    fn completing_below_the_split_field_only_collapses_more() {
        let data = levels::test_terrain();
        let settings = UdlodSettings::default();
        let levels = Levels::for_settings(&data, &settings).unwrap();
        let (mut today, mut below) = (0u32, [0u32; 3]);
        for (k, cam) in levels::test_poses().iter().enumerate() {
            let p = SelectionParams::new(&levels, &data, &settings, cam, cam.position, 640, 360);
            let tiles = select::select_tiles(&levels, &p);
            for t in &tiles {
                today += morph::tile_collapse_mask(&levels, &p, *t).count_ones();
            }
            for (n, terms) in CompletionTerms::ALL.into_iter().enumerate() {
                let completion = CompletionField::new(&levels, &p.field, terms);
                for &t in &tiles {
                    let now = morph::tile_collapse_mask(&levels, &p, t);
                    let then = completion.tile_collapse_mask(&levels, &p, t);
                    assert_eq!(
                        now & !then,
                        0,
                        "{terms:?}, pose {k}, tile {t:?}: {now:#x} -> {then:#x}"
                    );
                    below[n] += then.count_ones();
                }
            }
        }
        assert!(
            today > 0 && below[2] > today,
            "collapsed {today} -> {below:?}"
        );
    }
}
