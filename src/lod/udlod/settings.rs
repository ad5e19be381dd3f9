//! UDLOD's settings (config `[method] name = "udlod"`, `docs/udlod.md`).

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::gpu_constants::{UDLOD_MAX_LEVELS, UDLOD_SEED_TILES};
use crate::lod::sweep::Sweep;

/// `UdlodSettings::morph_levels()` for `morph_levels = 0`: every level a vertex can walk.
pub const MORPH_LEVELS_ALL: u32 = UDLOD_MAX_LEVELS;

#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct UdlodSettings {
    /// Quads per tile side: a power of two, 2..=64 (the draw masks' quadrants, the morph
    /// cascade's levels and the split field's cells divide it by powers of two). The crack,
    /// fold and popping tests cover grids 4 (the default) and 8; grid 2 draws fewer triangles
    /// but pops past the popping test's guard with the default morph (`docs/udlod-rounds.md`, "What
    /// sets the field; grid 2 with walks past the tile").
    pub grid_size: u32,
    /// Screen-space geometric error target in pixels.
    pub tau_px: f64,
    /// Fraction of each level's range over which vertices morph (0.05..=0.45).
    pub morph_range: f64,
    /// Levels over which a tile's vertices may morph (`docs/udlod-rounds.md`, "The morph cascade"
    /// and "Walks past the tile"): 0 (the default) every level, the morph cascade with vertices
    /// walking on past their tile (culling boxes grow to the corners' walks,
    /// `select::tile_reach`); `2..=`[`cascade_levels`] (grid 4: 2, grid 8: 3) at most that
    /// many, which keeps them inside their tile (the largest was the default until issue 18's
    /// fifteenth round); 1 one level step, the CDLOD-style chain, where neighbours differ by
    /// at most one level.
    pub morph_levels: u32,
    /// Split-field nodes per tile side (`docs/udlod-rounds.md`, "A finer split field"): 0 (the
    /// default) the density measured for the grid size ([`field_density`]: 2 at grid 4
    /// and 8, else 1); 1 at the tiles' corners; 2 also at their edges' midpoints and centres,
    /// each cell taking the error of its quarter of the tile, so a rough tile raises its
    /// neighbours' split distances over half a tile instead of a whole one: 6-22 % fewer
    /// triangles at grid 4 at about the same measured error (with its own share,
    /// [`worst_case_share`]), for 2.8x the host memory (`tests/hostmem.rs`) and
    /// statistics of `grid_size / 2` (`preprocess` stores grid 2's by default). Otherwise a power
    /// of two that leaves at least 2 quads per cell (`grid_size / field_density >= 2`).
    pub field_density: u32,
    /// The share of a tile's worst-case projected error the split rule spends on `tau`
    /// ([`worst_case_share`]): 0 (the default) the share measured per grid size and
    /// field density; a value
    /// in (0, 1] overrides it, for measuring it again (`eval --sweep worst_case_share=...`).
    pub worst_case_share: f64,
    /// The most tiles a frame and view may draw (the lists' capacity, at most the full
    /// tree's leaves).
    pub max_tiles: u32,
    /// 0 (the default): before each frame's prepass a slot's lists grow to a bound on what the
    /// view can reserve (`select::reserved_leaves_bound`), up to `max_tiles`, so no frame
    /// overflows. N > 0 (an ablation): they start at N tiles and grow only after a frame
    /// overflowed them (that frame is drawn coarser).
    pub initial_tiles: u32,
    /// Vertex morphing (off only to demonstrate popping and cracks in tests).
    pub morph: bool,
    /// Frustum culling of tiles.
    pub cull: bool,
    /// With `cull`, the quadrants of drawn tiles whose boxes lie outside the frustum are not
    /// drawn (`docs/udlod-rounds.md`, "Quadrants outside the view": the same image, fewer triangles
    /// where the view's edge cuts coarse tiles). Off only to measure it.
    pub cull_quadrants: bool,
    /// Which tiles are drawn with back-face culling.
    pub back_faces: BackFaces,
    /// Largest ratio between a level's largest split distance and a tile's own (the split
    /// field's cap; 1 = distance-only selection: every tile refined for the level's worst
    /// error and the chain). Larger lets smooth tiles keep coarser levels.
    pub error_field_max: f64,
    /// Draw each quadrant of a tile whose vertices odd at the tile's level all lie fully on its
    /// parent's grid as that grid (a quarter of the quadrant's triangles; the same surface,
    /// bit for bit: `docs/udlod-rounds.md`, "Collapsed quadrants"; at grid 2 whole tiles only). Off
    /// only to measure it.
    pub collapse: bool,
    /// Draw without an index buffer (six vertex-shader runs per quad) instead of the shared
    /// indexed grid; kept for measurement (`benches/udlod.rs` compares the two).
    pub vertex_pulling: bool,
    /// How LOD distances are measured on a native non-square grid on the earth (square grids
    /// have one spacing either way).
    pub lod_metric: LodMetric,
    /// Workgroups per row of the prepass's `refine` dispatches (1..=65535; default 65,535,
    /// the least `maxComputeWorkGroupCount` a Vulkan device may have): past it a dispatch takes
    /// more rows. Lowered only to exercise the rows in tests.
    pub dispatch_row: u32,
    /// The most tiles of the coarse levels the host walks before each frame and hands the
    /// prepass's first pass (`seed`; 1..=`UDLOD_SEED_TILES`, default 256): those levels cost
    /// no GPU passes. 1 hands it the root alone (every level a pass, what UDLOD did before;
    /// kept for measurement).
    pub seed_tiles: u32,
}

/// Which of UDLOD's tiles are drawn with back-face culling (config `back_faces`;
/// docs/udlod.md, "Pinholes far away").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum BackFaces {
    /// Tiles none of whose vertices is part-way through its morph (each unmorphed or fully on
    /// the parent's grid, as the prepass finds with the vertex stage's arithmetic): they have
    /// no sliver triangles, and culling them saves the rasterizer their hidden back faces.
    /// The other tiles' slivers, which can face away while on the surface, are drawn.
    #[default]
    Static,
    /// Every tile (an ablation: morphing slivers seen from far away leave pinholes).
    All,
    /// No tile (what UDLOD did before: every back face rasterized).
    None,
}

/// The LOD metric on a native non-square grid on the earth (config `lod_metric`;
/// docs/udlod-rounds.md, "Per-axis metric on the earth").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LodMetric {
    /// Each axis with its own smallest metric spacing on the drawn surface (east-west and
    /// north-south apart).
    #[default]
    Axis,
    /// Both axes with the grid's one smallest spacing (the east-west one at the poleward
    /// edge): an ablation, what UDLOD did before; north-south up to `1 / cos(lat)` finer
    /// than needed.
    Smallest,
}

impl Default for UdlodSettings {
    fn default() -> Self {
        UdlodSettings {
            // Grid 4 (issue 18): 1.2-1.5x fewer triangles than grid 8 at the same tau and
            // error, no slower since the prepass reserves per workgroup (docs/udlod.md,
            // "Grid 4 as the default").
            grid_size: 4,
            tau_px: 1.0,
            morph_range: 0.2,
            // The morph cascade (issue 18): up to 2x fewer triangles than one level step at
            // 640x360, -0.6 to -15 % at 1080p on the H200 (docs/udlod-rounds.md, "The morph
            // cascade").
            morph_levels: 0,
            // Two nodes per tile side at grid 4 and 8 (issue 18, nineteenth round): 6-22 % fewer
            // triangles at about equal measured error (docs/udlod-rounds.md, "The finer field as
            // the default").
            field_density: 0,
            worst_case_share: 0.0,
            // 16.8 M triangles of grid-4 tiles: Hedberg's uneven map at tau 0.5 and 1080p
            // needs 8.7 M and overflowed 262,144 tiles in every frame (docs/udlod.md).
            max_tiles: 524_288,
            initial_tiles: 0,
            morph: true,
            cull: true,
            cull_quadrants: true,
            back_faces: BackFaces::Static,
            error_field_max: 1024.0,
            collapse: true,
            vertex_pulling: false,
            lod_metric: LodMetric::Axis,
            dispatch_row: 65_535,
            seed_tiles: UDLOD_SEED_TILES,
        }
    }
}

impl UdlodSettings {
    /// What `vkterrain eval --sweep KEY=...` varies for UDLOD.
    pub const SWEEP: &[Sweep<Self>] = &[
        Sweep {
            key: "tau_px",
            help: "screen-space error target (px)",
            apply: |s, v| s.tau_px = v,
        },
        Sweep {
            key: "error_field_max",
            help: "split-field cap (1 = distance-only)",
            apply: |s, v| s.error_field_max = v,
        },
        Sweep {
            key: "grid_size",
            help: "quads per tile side",
            apply: |s, v| s.grid_size = v as u32,
        },
        Sweep {
            key: "field_density",
            help: "split-field nodes per tile side (0 = measured per grid size; 1, 2, ...)",
            apply: |s, v| s.field_density = v as u32,
        },
        Sweep {
            key: "worst_case_share",
            help: "share of a tile's worst-case error spent on tau (0 = measured per grid size and field density)",
            apply: |s, v| s.worst_case_share = v,
        },
        Sweep {
            key: "max_tiles",
            help: "tile budget per frame and view",
            apply: |s, v| s.max_tiles = v as u32,
        },
        Sweep {
            key: "collapse",
            help: "draw fully morphed tiles as their parent's grid (1, the default; 0 = off)",
            apply: |s, v| s.collapse = v != 0.0,
        },
        Sweep {
            key: "cull_quadrants",
            help: "leave out drawn tiles' quadrants outside the frustum (1, the default; 0 = off)",
            apply: |s, v| s.cull_quadrants = v != 0.0,
        },
        Sweep {
            key: "morph_range",
            help: "share of each level's range that morphs",
            apply: |s, v| s.morph_range = v,
        },
        Sweep {
            key: "morph_levels",
            help: "levels a vertex may morph over (0 = every level, the default; 1 = one step; up to log2(grid_size) = within its tile)",
            apply: |s, v| s.morph_levels = v as u32,
        },
        Sweep {
            key: "seed_tiles",
            help: "coarse levels' tiles walked on the host before the prepass (1 = the root only)",
            apply: |s, v| s.seed_tiles = v as u32,
        },
    ];

    /// Levels over which a tile's vertices morph: `morph_levels`, or with 0 every level
    /// ([`MORPH_LEVELS_ALL`]: no bound, the split field keeps no reach term).
    pub fn morph_levels(&self) -> u32 {
        match self.morph_levels {
            0 => MORPH_LEVELS_ALL,
            n => n,
        }
    }

    /// Split-field nodes per tile side: `field_density`, or with 0 the density measured for
    /// `grid_size` ([`field_density`]).
    pub fn field_density(&self) -> u32 {
        match self.field_density {
            0 => field_density(self.grid_size),
            d => d,
        }
    }

    /// The share of a tile's worst-case projected error spent on `tau`: `worst_case_share`,
    /// or with 0 the one measured for `grid_size` and the field density ([`worst_case_share`]).
    pub fn worst_case_share(&self) -> f64 {
        match self.worst_case_share {
            0.0 => worst_case_share(self.grid_size, self.field_density()),
            k => k,
        }
    }

    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::invalid("udlod settings", m));
        if !(2..=64).contains(&self.grid_size) || !self.grid_size.is_power_of_two() {
            return bad(format!(
                "grid_size {} must be a power of two within 2..=64",
                self.grid_size
            ));
        }
        if !(self.tau_px.is_finite() && self.tau_px >= 0.05 && self.tau_px <= 1000.0) {
            return bad(format!(
                "tau_px {} must be within 0.05..=1000 pixels",
                self.tau_px
            ));
        }
        if !(self.morph_range.is_finite() && (0.05..=0.45).contains(&self.morph_range)) {
            return bad(format!(
                "morph_range {} must be within 0.05..=0.45",
                self.morph_range
            ));
        }
        let most = cascade_levels(self.grid_size);
        if self.morph_levels > most {
            return bad(format!(
                "morph_levels {} must be 0 (every level) or within 1..={most} at grid_size {} (the most that keep vertices in their tile)",
                self.morph_levels, self.grid_size
            ));
        }
        let d = self.field_density();
        if !d.is_power_of_two() || self.grid_size % d != 0 || self.grid_size / d < 2 {
            return bad(format!(
                "field_density {d} must be 0 (measured per grid size) or a power of two with at least 2 quads per cell (grid_size {} / field_density >= 2)",
                self.grid_size
            ));
        }
        let k = self.worst_case_share;
        if !(k == 0.0 || (k > 0.0 && k <= 1.0)) {
            return bad(format!(
                "worst_case_share {k} must be 0 (measured per grid size and field density) or within (0, 1]"
            ));
        }
        if !(16..=1 << 22).contains(&self.max_tiles) {
            return bad(format!(
                "max_tiles {} must be within 16..=4194304",
                self.max_tiles
            ));
        }
        if self.initial_tiles != 0 && !(16..=self.max_tiles).contains(&self.initial_tiles) {
            return bad(format!(
                "initial_tiles {} must be 0 (max_tiles) or within 16..=max_tiles ({})",
                self.initial_tiles, self.max_tiles
            ));
        }
        if !(1..=65_535).contains(&self.dispatch_row) {
            return bad(format!(
                "dispatch_row {} must be within 1..=65535",
                self.dispatch_row
            ));
        }
        if !(1..=UDLOD_SEED_TILES).contains(&self.seed_tiles) {
            return bad(format!(
                "seed_tiles {} must be within 1..={UDLOD_SEED_TILES}",
                self.seed_tiles
            ));
        }
        if !(self.error_field_max.is_finite() && (1.0..=1024.0).contains(&self.error_field_max)) {
            return bad(format!(
                "error_field_max {} must be within 1..=1024",
                self.error_field_max
            ));
        }
        Ok(())
    }
}

/// The share of a tile's worst-case projected error that the split rule spends on `tau`, as a
/// function of the tile size (`grid_size`): `tau` is the 99.9th percentile of the
/// screen-space error, not its maximum. The worst case (the tile's largest error, seen from
/// its nearest point) overstates that percentile, the more the larger the tile: the largest
/// error sits at one of `(grid_size 2^l + 1)^2` samples, rarely the nearest one, and the
/// larger a tile the farther its worst sample may lie behind its nearest point and the
/// further its maximum lies in the tail of its samples' errors. Smaller tiles therefore need a
/// share nearer 1 (a larger split distance for the same error). Measured per grid size
/// (`docs/udlod-rounds.md`, "Issue 18, third round"): with these shares the 99.9th percentile lands
/// in [0.5, 1] tau where the pixel target (not the crack-free chain or the data's resolution)
/// sets the distances (on the CI data at grid 2, 4 and 8; on other data sets more pixels are
/// exact and the percentile lower); single pixels may exceed tau. Grid sizes between the
/// measured ones interpolate in `log2(grid_size)`; larger ones take the grid-8 share (larger
/// tiles should overstate more, so that refines them more than needed; not measured).
///
/// With a finer split field (`field_density` `d > 1`) each field cell takes the error of its
/// own part of the tile: the field dilates less around rough spots, and the selection spends
/// more of tau with the same share (grid 4, two nodes per side, at 0.72: p99.9 1.085 px at tau
/// 1 on the CI flight). Those densities take their own measured shares
/// ([`FINER_FIELD_SHARES`]); unmeasured ones the largest measured share of all (0.9, grid 2's:
/// the most refinement, conservative).
///
/// The only place the share enters: [`SplitField::new`](super::field::SplitField::new) bakes it (through [`FieldKey::share`](super::field::FieldKey::share),
/// which `UdlodSettings::worst_case_share` may override) into the split field that the CPU
/// reference selection and the GPU prepass both read.
pub fn worst_case_share(grid_size: u32, field_density: u32) -> f64 {
    if field_density > 1 {
        return FINER_FIELD_SHARES
            .iter()
            .find(|&&(g, d, _)| g == grid_size && d == field_density)
            .map_or(MEASURED_SHARES[0].1, |&(_, _, k)| k);
    }
    tile_share(grid_size)
}

/// `(grid_size, share)` with one field node per tile corner, increasing grid sizes
/// ([`worst_case_share`]).
const MEASURED_SHARES: [(u32, f64); 3] = [(2, 0.9), (4, 0.72), (8, 0.7)];

/// `(grid_size, field_density, share)` measured for the finer split field on the CI flight
/// (640x360, `vkterrain eval --config config/ci.toml --earth flat --methods udlod --sweep
/// grid_size=G --sweep field_density=D --sweep worst_case_share=... --sweep
/// tau_px=0.5,1,2,4`; docs/udlod-rounds.md, "What the tiles could draw", eighteenth round): a swept
/// share whose p99.9 stays within tau at every tau. Grid 4, two per side: 0.76 exceeded it
/// (1.010 px at tau 1), 0.78 reached 0.997 tau at tau 2, so 0.80 (at most 0.973 tau); grid 8,
/// two or four per side: 0.70 exceeded it, 0.76 held (0.70 / 0.76 / 0.82 swept).
pub const FINER_FIELD_SHARES: [(u32, u32, f64); 3] = [(4, 2, 0.80), (8, 2, 0.76), (8, 4, 0.76)];

/// The split field's nodes per tile side where `UdlodSettings::field_density` is 0: two at the
/// grid sizes whose share was measured with two ([`FINER_FIELD_SHARES`]: grid 4 and 8), one
/// elsewhere (grid 2 leaves no room for two cells of 2 quads; larger grids are not measured).
/// Two per side draws 6-22 % fewer triangles than one at grid 4 at about equal measured error
/// (docs/udlod-rounds.md, "The finer field as the default").
pub fn field_density(grid_size: u32) -> u32 {
    if FINER_FIELD_SHARES
        .iter()
        .any(|&(g, d, _)| g == grid_size && d == 2)
    {
        2
    } else {
        1
    }
}

/// The share with one field node per tile corner, interpolated between the measured grid sizes.
fn tile_share(grid_size: u32) -> f64 {
    let g = grid_size.clamp(
        MEASURED_SHARES[0].0,
        MEASURED_SHARES[MEASURED_SHARES.len() - 1].0,
    );
    let i = MEASURED_SHARES
        .iter()
        .position(|&(m, _)| m >= g)
        .unwrap_or(0);
    if MEASURED_SHARES[i].0 == g || i == 0 {
        return MEASURED_SHARES[i].1;
    }
    let ((g0, k0), (g1, k1)) = (MEASURED_SHARES[i - 1], MEASURED_SHARES[i]);
    let t = (g as f64 / g0 as f64).log2() / (g1 as f64 / g0 as f64).log2();
    k0 + (k1 - k0) * t
}

/// Levels over which a tile's vertices may morph and stay inside the tile: the power of two in
/// `grid_size` (a tile of level `a` starts at a multiple of `grid_size 2^a` samples; a vertex
/// odd at level `j` slides `2^j` towards the tile's origin, onto a multiple of `2^(j + 1)`).
pub fn cascade_levels(grid_size: u32) -> u32 {
    grid_size.trailing_zeros().max(1)
}

#[cfg(test)]
mod tests {
    use super::{UdlodSettings, worst_case_share};

    /// 0 takes the share measured for the grid, a value in (0, 1] overrides it, and anything
    /// else is a one-line error naming the setting.
    #[test]
    fn worst_case_share_is_measured_or_overridden_within_0_1() {
        let at = |k: f64| UdlodSettings {
            worst_case_share: k,
            ..UdlodSettings::default()
        };
        let measured = worst_case_share(4, 2);
        assert_eq!(at(0.0).worst_case_share(), measured, "the default's field");
        let corners = UdlodSettings {
            field_density: 1,
            ..at(0.0)
        };
        assert_eq!(corners.worst_case_share(), worst_case_share(4, 1));
        assert_eq!(at(0.5).worst_case_share(), 0.5);
        for ok in [0.0, 0.3, 1.0] {
            assert!(at(ok).validate().is_ok(), "{ok}");
        }
        for bad in [-0.1, 1.5, f64::NAN, f64::INFINITY] {
            let e = at(bad).validate().unwrap_err().to_string();
            assert!(e.contains("worst_case_share") && !e.contains('\n'), "{e}");
        }
    }

    /// The host's walk hands the first pass 1..=`UDLOD_SEED_TILES` tiles (the seed buffer's
    /// size); 0 or more than that is a one-line error naming the setting.
    #[test]
    fn seed_tiles_is_within_1_and_the_seed_buffer() {
        use crate::gpu_constants::UDLOD_SEED_TILES;
        let at = |n: u32| UdlodSettings {
            seed_tiles: n,
            ..UdlodSettings::default()
        };
        for ok in [1, 16, UDLOD_SEED_TILES] {
            assert!(at(ok).validate().is_ok(), "{ok}");
        }
        for bad in [0, UDLOD_SEED_TILES + 1, u32::MAX] {
            let e = at(bad).validate().unwrap_err().to_string();
            assert!(e.contains("seed_tiles") && !e.contains('\n'), "{e}");
        }
    }

    /// Grid sizes are powers of two in 2..=64: grid 6 drew 13,724 hole pixels with collapsed
    /// quadrants over 10 CI frames at 320x180 (a quadrant of 3 quads has no parent grid), and
    /// the split field's cell lookup shifts by the cell's span. Anything else is a one-line
    /// error naming the setting.
    #[test]
    fn grid_size_is_a_power_of_two_within_2_64() {
        let at = |g: u32| UdlodSettings {
            grid_size: g,
            ..UdlodSettings::default()
        };
        for ok in [2, 4, 8, 16, 32, 64] {
            assert!(at(ok).validate().is_ok(), "{ok}");
        }
        for bad in [0, 1, 6, 12, 48, 128] {
            let e = at(bad).validate().unwrap_err().to_string();
            assert!(e.contains("grid_size") && !e.contains('\n'), "{e}");
        }
    }

    /// The measured shares are where `docs/udlod.md` says, in (0, 1], never larger for a
    /// larger tile (the worst case overstates more), and interpolated between.
    #[test]
    fn worst_case_share_falls_with_the_tile_size() {
        assert_eq!(
            [2, 4, 8].map(|g| worst_case_share(g, 1)),
            [0.9, 0.72, 0.7],
            "docs/udlod.md's table"
        );
        let mut last = 1.0;
        for g in (2..=64).step_by(2) {
            let k = worst_case_share(g, 1);
            assert!(k > 0.0 && k <= last, "grid {g}: share {k} after {last}");
            last = k;
        }
        let k6 = worst_case_share(6, 1);
        assert!(k6 > 0.7 && k6 < 0.72, "grid 6: {k6}");
    }

    /// A finer split field spends more of tau at the same share, so its measured share is
    /// larger than its grid's corner-field share (a smaller one let the CI flight's p99.9
    /// exceed tau: docs/udlod-rounds.md, "What the tiles could draw"), and an unmeasured density
    /// takes the largest share measured at all.
    #[test]
    fn finer_fields_take_their_own_larger_shares() {
        assert_eq!(worst_case_share(4, 2), 0.80, "measured");
        assert_eq!(
            [worst_case_share(8, 2), worst_case_share(8, 4)],
            [0.76, 0.76]
        );
        for (g, d, k) in super::FINER_FIELD_SHARES {
            assert!(k > worst_case_share(g, 1), "grid {g} density {d}: {k}");
        }
        assert_eq!(worst_case_share(16, 2), 0.9, "unmeasured: grid 2's");
        assert_eq!(worst_case_share(16, 1), worst_case_share(8, 1));
    }

    /// The measured field density (`field_density = 0`) is two nodes per side exactly where a
    /// share was measured for two, one elsewhere; and it is valid at every grid size, so a sweep
    /// over grid sizes never meets an invalid default (grid 2 has no room for two cells).
    /// Negative control: two per side at grid 2 fails `validate`.
    #[test]
    fn the_measured_field_density_is_two_where_its_share_was_measured() {
        let densities = [2, 4, 8, 16, 32, 64].map(super::field_density);
        assert_eq!(densities, [1, 2, 2, 1, 1, 1]);
        for g in [2, 4, 8, 16, 32, 64] {
            let s = UdlodSettings {
                grid_size: g,
                ..UdlodSettings::default()
            };
            assert_eq!(s.field_density(), super::field_density(g));
            assert!(s.validate().is_ok(), "grid {g}");
            let d = s.field_density();
            assert!(
                d == 1 || super::FINER_FIELD_SHARES.contains(&(g, d, s.worst_case_share())),
                "grid {g}: density {d} without its measured share"
            );
        }
        let two_at_grid_2 = UdlodSettings {
            grid_size: 2,
            field_density: 2,
            ..UdlodSettings::default()
        };
        let e = two_at_grid_2.validate().unwrap_err().to_string();
        assert!(e.contains("field_density 2") && !e.contains('\n'), "{e}");
    }
}
