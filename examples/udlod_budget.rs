//! Where UDLOD's triangles go: per data set the field cells' own errors per level; per tau the
//! split-distance table (which term sets each level), the drawn tiles' projected-error slack,
//! counterfactual selections and the oracle's count, the least the tiles could draw (the tile
//! oracle with quadrants collapsed wherever the parent grid is within tau) and how many drawn
//! quadrants are within tau on the parent grid but drawn uncollapsed, the drawn triangles
//! with every quadrant drawn (no quadrant culled outside the frustum) and the draw masks in
//! use, the drawn triangles were the morph to complete at a field below the split field
//! (`udlod::completion`, a what-if), and the prepass's seed
//! (the coarse levels the host walks: its tiles, the GPU passes left, the walk's host time).
//! CPU only (the CPU reference selection equals the GPU's; tests/udlod.rs).
//!
//!   cargo run --release --example udlod_budget -- --config config/ci.toml [--frames 6] [--tau 1,2,4]
//!     [--grid 4] [--morph-levels 0] [--field-density 2] [--share K] [--width 640 --height 360]
//!     [--earth flat|ellipsoid]   (the scenario's geometry: Fischer S1/S3 fly `--earth flat`)
//!     [--zone-rule width|error-scaled|free]   (how the field charges the morph zone's width:
//!     `field::ZoneRule`; anything but `width` is a what-if the renderer does not draw)

use std::collections::{HashMap, HashSet};
use std::path::PathBuf;
use std::sync::Arc;

use vkterrain::cli::render::{RenderArgs, prepare};
use vkterrain::dataset::Heightmap;
use vkterrain::eval::oracle::Oracle;
use vkterrain::lod::udlod::completion::{CompletionField, CompletionTerms};
use vkterrain::lod::udlod::field::{FieldKey, FieldTerm, SplitField, ZoneRule};
use vkterrain::lod::udlod::grid::{QuadrantDraw, TileMask};
use vkterrain::lod::udlod::levels::{Levels, Tile};
use vkterrain::lod::udlod::params::SelectionParams;
use vkterrain::lod::udlod::select;
use vkterrain::lod::udlod::{field, grid, levels, morph, seed};
use vkterrain::lod::{MethodConfig, UdlodSettings};
use vkterrain::render::EarthGeometry;
use vkterrain::scene::Camera;

fn main() -> anyhow::Result<()> {
    let args = Args::parse(std::env::args().skip(1))?;
    let p = prepare(&RenderArgs {
        config: args.config.clone(),
        scenario: args.scenario.clone(),
        width: args.width,
        height: args.height,
        earth: args.earth,
        ..Default::default()
    })?;
    let data = p.data.require_grid("udlod_budget")?.clone();
    let settings = args.settings(&p.config.method)?;
    let (w, h) = (p.config.render.width, p.config.render.height);
    let t0 = std::time::Instant::now();
    let levels = Levels::for_settings(&*data, &settings)?;
    let t1 = std::time::Instant::now();
    let oracle = Oracle::new(&data);
    println!(
        "{} {}x{} spacing {} m; levels {:.2}s oracle {:.2}s; grid {} field_max {} morph_range {}; {}x{} frames {}",
        data.name,
        data.width,
        data.height,
        data.spacing,
        (t1 - t0).as_secs_f64(),
        t1.elapsed().as_secs_f64(),
        settings.grid_size,
        settings.error_field_max,
        settings.morph_range,
        w,
        h,
        p.frames
    );
    print_cell_errors(&levels);
    let focal = p.scenario.camera(0).focal_px(h);
    let picks: Vec<u64> = (0..args.frames)
        .map(|i| (i as u64 * p.frames as u64) / args.frames as u64)
        .collect();
    let cams: Vec<Camera> = picks.iter().map(|&k| p.scenario.camera(k)).collect();
    for &tau in &args.taus {
        println!("\n== tau {tau} px (focal {focal:.1} px)");
        let v = TauView::new(
            &levels,
            &data,
            &settings,
            args.zone_rule,
            &cams,
            focal,
            tau,
            (w, h),
        );
        v.print_field_terms();
        let drawn = Drawn::over_frames(&v, &oracle);
        drawn.print_chain_and_seed(&v);
        let tris_o = drawn.oracle_triangles;
        v.print_counterfactual_fields(tris_o);
        v.print_cell_fields(tris_o);
        v.print_own_need(tris_o);
        v.print_tile_oracles(tris_o);
        v.print_sub_rectangles(tris_o);
        if drawn.tiles == 0 {
            // Nothing in view (e.g. the scenario's cameras are in the other earth geometry's
            // frame): no ratio or quantile to print.
            println!("  no tile drawn in frames {picks:?} (is `--earth` the scenario's?)");
            continue;
        }
        drawn.print_summary(&v, &picks);
    }
    Ok(())
}

/// The command line (the module's docs list the flags).
struct Args {
    config: Option<PathBuf>,
    scenario: Option<PathBuf>,
    /// How many evenly spaced frames of the flight are measured.
    frames: usize,
    taus: Vec<f64>,
    grid: Option<u32>,
    morph_levels: Option<u32>,
    field_density: Option<u32>,
    share: Option<f64>,
    zone_rule: ZoneRule,
    width: Option<u32>,
    height: Option<u32>,
    earth: Option<EarthGeometry>,
}

impl Args {
    fn parse(mut args: impl Iterator<Item = String>) -> anyhow::Result<Args> {
        let mut out = Args {
            config: None,
            scenario: None,
            frames: 6,
            taus: vec![0.5, 1.0, 2.0, 4.0],
            grid: None,
            morph_levels: None,
            field_density: None,
            share: None,
            zone_rule: ZoneRule::Width,
            width: None,
            height: None,
            earth: None,
        };
        while let Some(a) = args.next() {
            // The value after a flag, or an error naming the flag (no panics on bad input).
            let mut value = |what: &str| {
                args.next()
                    .ok_or_else(|| anyhow::anyhow!("{a} needs {what}"))
            };
            match a.as_str() {
                "--config" => out.config = Some(PathBuf::from(value("a path")?)),
                "--scenario" => out.scenario = Some(PathBuf::from(value("a path")?)),
                "--grid" => out.grid = Some(parse(&a, &value("a number")?)?),
                "--morph-levels" => out.morph_levels = Some(parse(&a, &value("a number")?)?),
                "--field-density" => out.field_density = Some(parse(&a, &value("a number")?)?),
                "--share" => out.share = Some(parse(&a, &value("a number")?)?),
                "--zone-rule" => out.zone_rule = zone_rule(&value("width, error-scaled or free")?)?,
                "--earth" => out.earth = Some(earth(&value("ellipsoid or flat")?)?),
                "--frames" => out.frames = parse(&a, &value("a number")?)?,
                "--width" => out.width = Some(parse(&a, &value("a number")?)?),
                "--height" => out.height = Some(parse(&a, &value("a number")?)?),
                "--tau" => {
                    out.taus = value("taus, comma-separated")?
                        .split(',')
                        .map(|s| parse(&a, s))
                        .collect::<anyhow::Result<_>>()?
                }
                _ => anyhow::bail!("unknown argument {a}"),
            }
        }
        Ok(out)
    }

    /// The config's UDLOD settings (the defaults for another method) with this command
    /// line's overrides, checked.
    fn settings(&self, method: &MethodConfig) -> anyhow::Result<UdlodSettings> {
        let mut settings = match method {
            MethodConfig::Udlod(s) => s.clone(),
            _ => UdlodSettings::default(),
        };
        if let Some(g) = self.grid {
            settings.grid_size = g;
        }
        if let Some(q) = self.morph_levels {
            settings.morph_levels = q;
        }
        if let Some(d) = self.field_density {
            settings.field_density = d;
        }
        if let Some(k) = self.share {
            settings.worst_case_share = k;
        }
        settings.validate()?;
        Ok(settings)
    }
}

fn zone_rule(text: &str) -> anyhow::Result<ZoneRule> {
    Ok(match text {
        "width" => ZoneRule::Width,
        "error-scaled" => ZoneRule::ErrorScaled,
        "free" => ZoneRule::Free,
        r => anyhow::bail!("--zone-rule {r}: width, error-scaled or free"),
    })
}

fn earth(text: &str) -> anyhow::Result<EarthGeometry> {
    Ok(match text {
        "ellipsoid" => EarthGeometry::Ellipsoid,
        "flat" => EarthGeometry::Flat,
        e => anyhow::bail!("--earth {e}: ellipsoid or flat"),
    })
}

/// One tau over the measured frames: the split field (with `--zone-rule` a what-if one) and
/// the cameras that every selection below reads.
struct TauView<'a> {
    levels: &'a Levels,
    data: &'a Heightmap,
    /// The settings at this tau.
    settings: UdlodSettings,
    field: Arc<SplitField>,
    cams: &'a [Camera],
    focal: f64,
    tau: f64,
    size: (u32, u32),
}

impl<'a> TauView<'a> {
    #[allow(clippy::too_many_arguments)]
    fn new(
        levels: &'a Levels,
        data: &'a Heightmap,
        settings: &UdlodSettings,
        zone_rule: ZoneRule,
        cams: &'a [Camera],
        focal: f64,
        tau: f64,
        size: (u32, u32),
    ) -> Self {
        let settings = UdlodSettings {
            tau_px: tau,
            ..settings.clone()
        };
        let key = FieldKey {
            zone_rule,
            ..FieldKey::new(&settings, focal)
        };
        let field = Arc::new(SplitField::new(levels, key));
        TauView {
            levels,
            data,
            settings,
            field,
            cams,
            focal,
            tau,
            size,
        }
    }

    /// The selection's parameters for `cam`, its reference height the data's under it.
    fn params(&self, cam: &Camera) -> SelectionParams {
        let z_ref = self.data.height_at(cam.position.x, cam.position.y);
        let (w, h) = self.size;
        SelectionParams::with_reference(
            self.levels,
            self.field.clone(),
            z_ref,
            &self.settings,
            cam,
            cam.position,
            w,
            h,
        )
    }

    /// A whole tile's triangles.
    fn triangles_per_tile(&self) -> u64 {
        2 * (self.levels.grid_size as u64).pow(2)
    }

    /// The tiles over all frames of the selection whose tiles split where `splits` says.
    fn count_tiles(&self, splits: impl Fn(&SelectionParams, &Camera, Tile) -> bool) -> usize {
        self.cams
            .iter()
            .map(|cam| {
                let sp = self.params(cam);
                select_generic(self.levels, &sp, |t| splits(&sp, cam, t)).len()
            })
            .sum()
    }

    /// Which term sets each field cell's split distance (every cell of the level, not only
    /// those in view), and the corners the gentle morph or the cap raised past them.
    fn print_field_terms(&self) {
        let (levels, field) = (self.levels, &self.field);
        let terms = field::field_terms(levels, field);
        // Level 0's field is all ones and not stored.
        for (l, t) in terms.iter().enumerate().skip(1) {
            let screen = levels.level_error[l] * self.focal / self.tau;
            let (nx, ny) = levels.field_cells_per_side(l as u32);
            let off = field.corner_offsets[l] as usize;
            let m = &field.corners[off..off + ((nx + 1) * (ny + 1)) as usize];
            println!(
                "  level {l}: e {:8.3} m  D {:9.1}  screen {:9.1}  extent {:8.1}  field max {:.1}  \
                 cells set by {} {}  corners raised {} of {}",
                levels.level_error[l],
                field.split[l],
                screen,
                levels.tile_extent(l as u32),
                m.iter().copied().fold(1.0, f32::max),
                FieldTerm::ALL.map(|f| f.name()).join("/"),
                t.cells.map(|n| n.to_string()).join("/"),
                t.corners_raised,
                t.corners,
            );
        }
    }

    /// Counterfactual split fields (`Cf`): the old rule and each change of the first rounds.
    fn print_counterfactual_fields(&self, tris_o: u64) {
        let keep = 1.0 - self.settings.morph_range;
        let base = Cf {
            beta: 1.0 / keep,
            chain: true,
            per_tile: true,
            cap: 1e9,
            morph_range: self.settings.morph_range,
            box_dist: false,
            diam3d: false,
        };
        let linear = Cf { beta: 1.0, ..base };
        let unchained = Cf {
            chain: false,
            ..linear
        };
        let variants = [
            (
                "level error, chain, ref height",
                Cf {
                    per_tile: false,
                    ..base
                },
            ),
            ("per-tile error, chain, beta 1/(1-r)", base),
            ("per-tile error, chain, beta 1", linear),
            (
                "per-tile, chain, beta 1, r 0.1",
                Cf {
                    morph_range: 0.1,
                    ..linear
                },
            ),
            (
                "per-tile, chain, beta 1, box dist, 3d diam",
                Cf {
                    box_dist: true,
                    diam3d: true,
                    ..linear
                },
            ),
            ("per-tile, no chain, beta 1", unchained),
            (
                "per-tile, no chain, beta 1, box",
                Cf {
                    box_dist: true,
                    ..unchained
                },
            ),
        ];
        for (name, cf) in variants {
            let f = sfield(self.levels, self.focal, self.tau, cf);
            let n = self.count_tiles(|sp, cam, t| cf_splits(self.levels, sp, cam, &f, cf, t));
            print_cf(name, n, self.triangles_per_tile(), tris_o);
        }
    }

    /// Counterfactual fields with a node every `ns` quads (`cell_field`).
    fn print_cell_fields(&self, tris_o: u64) {
        let levels = self.levels;
        for (name, ns, ratio) in [
            ("node every cell, nest", 1u32, 0.0),
            ("node every cell, nest, gentle 1.25", 1, 1.25),
            ("node every 2 cells, nest", 2, 0.0),
            ("node every 2 cells, nest, gentle 1.56", 2, 1.5625),
            ("node every tile, nest", levels.grid_size, 0.0),
        ] {
            if ns > levels.grid_size {
                continue;
            }
            let scale = self.settings.worst_case_share() * self.focal / self.tau;
            let cf = cell_field(levels, self.data, scale, ns, ratio);
            let n = self.count_tiles(|sp, _, t| {
                let l = t.lod as usize;
                let g = levels.grid_size / ns;
                let (w1, h1) = cf[l].1;
                let mut mx = 0.0f64;
                for j in t.y * g..=((t.y + 1) * g).min(h1 - 1) {
                    for i in t.x * g..=((t.x + 1) * g).min(w1 - 1) {
                        mx = mx.max(cf[l].0[(j * w1 + i) as usize]);
                    }
                }
                (select::tile_distance(levels, sp, t) as f64) < mx
            });
            print_cf(name, n, self.triangles_per_tile(), tris_o);
        }
    }

    /// Each tile split by its own need alone (no chain), worst case or the split rule's share.
    fn print_own_need(&self, tris_o: u64) {
        let levels = self.levels;
        for (name, kk, boxd) in [
            ("own need k=1, ref dist", 1.0, false),
            (
                "own need k=share, ref dist",
                self.settings.worst_case_share(),
                false,
            ),
            ("own need k=1, box dist", 1.0, true),
        ] {
            let n = self.count_tiles(|sp, cam, t| {
                let need = kk * levels.tile_error(t) as f64 * self.focal / self.tau;
                let d = if boxd {
                    box_distance(levels, cam, t)
                } else {
                    select::tile_distance(levels, sp, t) as f64
                };
                d < need
            });
            print_cf(name, n, self.triangles_per_tile(), tris_o);
        }
    }

    /// The tile oracle (exact per-sample errors, no chain or morph), and the least UDLOD's
    /// tiles could draw: its tiles, each quadrant drawn as the parent's grid wherever that
    /// grid is within tau at every sample.
    fn print_tile_oracles(&self, tris_o: u64) {
        let levels = self.levels;
        let (mut n, mut tris) = (0usize, 0u64);
        for cam in self.cams {
            let sp = self.params(cam);
            let view = ExactView::new(self.data, cam, self.focal, self.tau);
            let tiles = select_generic(levels, &sp, |t| view.tile_splits(levels, t));
            n += tiles.len();
            for t in tiles {
                let bits = (0..4u32)
                    .filter(|&q| view.quadrant_within_tau(levels, t, q))
                    .fold(0u32, |m, q| m | 1 << q);
                let mask = TileMask::new(levels.grid_size, bits, 0);
                tris += grid::mask_triangles(levels.grid_size, mask);
            }
        }
        print_cf(
            "tile oracle (exact per-sample, no chain/morph)",
            n,
            self.triangles_per_tile(),
            tris_o,
        );
        println!(
            "  cf tile oracle, quadrants collapsed where the parent grid is within tau: triangles {tris} ratio {:.2}",
            tris as f64 / tris_o as f64
        );
    }

    /// The split test over `sub` x `sub` sub-rectangles of each tile (`sub_rect_splits`).
    fn print_sub_rectangles(&self, tris_o: u64) {
        let levels = self.levels;
        for sub in [1u32, 2, 4, 8] {
            let (mut n, mut tris) = (0usize, 0u64);
            for cam in self.cams {
                let sp = self.params(cam);
                let tiles = select_generic(levels, &sp, |t| sub_rect_splits(levels, &sp, t, sub));
                n += tiles.len();
                for t in &tiles {
                    let mask = select::tile_mask(levels, &sp, *t);
                    tris += grid::mask_triangles(levels.grid_size, mask);
                }
            }
            println!(
                "  cf split test per {sub}x{sub} sub-rectangles: tiles {n} triangles uncollapsed {} collapsed {tris} ratio {:.2}",
                n as u64 * self.triangles_per_tile(),
                tris as f64 / tris_o as f64
            );
        }
    }
}

/// What the renderer draws at one tau over the measured frames, with the oracle's count.
#[derive(Default)]
struct Drawn {
    tiles: usize,
    oracle_triangles: u64,
    per_level: Vec<usize>,
    /// Per drawn tile, its projected-error bound / tau at its nearest sample (`tile_slack`).
    slack: Vec<f64>,
    /// Per drawn tile with an error: how tight the worst case is (the largest exact
    /// per-sample projected error / the tile's error at its nearest sample) and how far its
    /// worst sample lies behind its nearest point (nearest distance / worst sample's).
    tight: Vec<f64>,
    behind: Vec<f64>,
    /// Drawn tiles whose parent's exact per-sample projected error is within tau (the parent
    /// alone would do): split by the parent's own pixel term (rule looseness) or only by the
    /// crack-free chain.
    over_rule: usize,
    over_chain: usize,
    /// Triangles as drawn (quadrants whose odd vertices all lie fully on the parent's grid
    /// drawn as that grid, those outside the frustum not at all: `select::tile_mask`), and the
    /// quadrants collapsed.
    drawn_triangles: u64,
    collapsed_quadrants: u32,
    /// Collapsing whole tiles only (the tenth round's build), for comparison.
    whole_triangles: u64,
    whole_tiles: usize,
    /// Drawn quadrants whose parent grid is within tau at every sample, and of those the
    /// ones drawn uncollapsed (the morph not complete there).
    within: u32,
    within_uncollapsed: u32,
    /// Triangles with every quadrant of the drawn tiles drawn (`cull_quadrants = false`).
    all_quadrant_triangles: u64,
    /// Draw masks in use summed over the frames (each an indirect draw per pipeline that has
    /// such tiles), with and without the quadrants outside the frustum dropped.
    masks_used: usize,
    masks_used_all: usize,
    /// Per frame, the prepass's seed (`timed_seed`).
    seeds: Vec<(usize, u32, f64)>,
}

impl Drawn {
    fn over_frames(v: &TauView, oracle: &Oracle) -> Drawn {
        let mut d = Drawn {
            per_level: vec![0; v.levels.levels() as usize],
            ..Default::default()
        };
        for cam in v.cams {
            let sp = v.params(cam);
            d.seeds
                .push(timed_seed(v.levels, &sp, v.settings.seed_tiles));
            let tiles = select::select_tiles(v.levels, &sp);
            d.tiles += tiles.len();
            let view = ExactView::new(v.data, cam, v.focal, v.tau);
            d.add_masks(v, &sp, &view, &tiles);
            d.add_errors(v, &sp, cam, &view, &tiles);
            let (w, h) = v.size;
            d.oracle_triangles += oracle.count(v.data, cam, w, h, v.tau).triangles;
        }
        d
    }

    /// One frame's tiles as drawn: their masks, triangles and collapsed quadrants.
    fn add_masks(&mut self, v: &TauView, sp: &SelectionParams, view: &ExactView, tiles: &[Tile]) {
        let levels = v.levels;
        let g = levels.grid_size;
        let (mut used, mut used_all) = (HashSet::new(), HashSet::new());
        for t in tiles {
            let mask = select::tile_mask(levels, sp, *t);
            self.drawn_triangles += grid::mask_triangles(g, mask);
            self.collapsed_quadrants += mask.quadrants(QuadrantDraw::Collapsed).count_ones();
            let own = mask.quadrants(QuadrantDraw::Own);
            for q in 0..4u32 {
                if view.quadrant_within_tau(levels, *t, q) {
                    self.within += 1;
                    self.within_uncollapsed += (own & 1 << q != 0) as u32;
                }
            }
            let collapsing = morph::tile_collapse_mask(levels, sp, *t);
            self.all_quadrant_triangles += grid::mask_triangles(g, TileMask::new(g, collapsing, 0));
            used.insert(mask);
            used_all.insert(TileMask::new(g, collapsing, 0));
            let whole = (collapsing == grid::ALL_QUADRANTS) as u32 * collapsing;
            self.whole_triangles += grid::mask_triangles(g, TileMask::new(g, whole, 0));
            self.whole_tiles += (whole != 0) as usize;
        }
        self.masks_used += used.len();
        self.masks_used_all += used_all.len();
    }

    /// One frame's tiles against the exact surface: their slack, the worst case's tightness
    /// and whether their parent would have done.
    fn add_errors(
        &mut self,
        v: &TauView,
        sp: &SelectionParams,
        cam: &Camera,
        view: &ExactView,
        tiles: &[Tile],
    ) {
        let levels = v.levels;
        let mut parents = HashMap::new();
        for t in tiles {
            let bound = tile_slack(levels, v.data, cam, v.focal, v.tau, *t);
            self.slack.push(bound);
            if bound > 0.0 {
                let (exact, near_over_worst) = tile_exact(levels, v.data, cam, v.focal, *t);
                self.tight.push(exact / v.tau / bound);
                self.behind.push(near_over_worst);
            }
            self.per_level[t.lod as usize] += 1;
            if t.lod >= levels.root_lod {
                continue;
            }
            let q = Tile {
                x: t.x / 2,
                y: t.y / 2,
                lod: t.lod + 1,
            };
            if *parents
                .entry(q)
                .or_insert_with(|| view.tile_splits(levels, q))
            {
                continue;
            }
            let screen =
                v.settings.worst_case_share() * levels.tile_error(q) as f64 * v.focal / v.tau;
            if (select::tile_distance(levels, sp, q) as f64) < screen {
                self.over_rule += 1;
            } else {
                self.over_chain += 1;
            }
        }
    }

    fn print_chain_and_seed(&self, v: &TauView) {
        println!(
            "  drawn tiles per level (0..root): {:?}; whose parent meets tau exactly: {} by its pixel term, {} only by the chain (of {})",
            self.per_level, self.over_rule, self.over_chain, self.tiles
        );
        let column = |f: fn(&(usize, u32, f64)) -> String| -> Vec<String> {
            self.seeds.iter().map(f).collect()
        };
        println!(
            "  seed ({} tiles at most): tiles {:?}, GPU passes {:?} of {} levels, host walk {:?} us (median of 200, flat world)",
            v.settings.seed_tiles,
            column(|x| x.0.to_string()),
            column(|x| x.1.to_string()),
            v.levels.levels(),
            column(|x| format!("{:.1}", x.2)),
        );
    }

    /// The drawn triangles and their counterfactuals against the oracle, and the tiles'
    /// error quantiles.
    fn print_summary(mut self, v: &TauView, picks: &[u64]) {
        let tris_o = self.oracle_triangles;
        let ratio = |tris: u64| tris as f64 / tris_o as f64;
        let g2 = v.triangles_per_tile();
        println!(
            "  drawn, collapsed quadrants as their parent's grid: {} of {} quadrants, triangles {} ratio {:.2}",
            self.collapsed_quadrants,
            self.tiles * 4,
            self.drawn_triangles,
            ratio(self.drawn_triangles)
        );
        // A quadrant is a quarter of the tile's `g2` triangles, collapsed a sixteenth.
        let if_collapsed =
            self.drawn_triangles - self.within_uncollapsed as u64 * (g2 / 4 - g2 / 16);
        println!(
            "  drawn quadrants whose parent grid is within tau: {} of {}, {} of them uncollapsed; those collapsed too: triangles {if_collapsed} ratio {:.2}",
            self.within,
            self.tiles * 4,
            self.within_uncollapsed,
            ratio(if_collapsed)
        );
        let views: Vec<_> = v.cams.iter().map(|cam| v.params(cam)).collect();
        print_completion_counts(v.levels, &v.field, &views, tris_o);
        println!(
            "  cf every quadrant of the drawn tiles drawn (cull_quadrants = false): triangles {} ratio {:.2}; draw masks in use over the frames {} ({} with every quadrant drawn)",
            self.all_quadrant_triangles,
            ratio(self.all_quadrant_triangles),
            self.masks_used,
            self.masks_used_all
        );
        println!(
            "  cf collapsing whole tiles only: {} of {} tiles, triangles {} ratio {:.2}",
            self.whole_tiles,
            self.tiles,
            self.whole_triangles,
            ratio(self.whole_triangles)
        );
        let uncollapsed = self.tiles as u64 * g2;
        println!(
            "  frames {picks:?}: tiles {} triangles uncollapsed {uncollapsed} oracle {tris_o} ratio {:.2}",
            self.tiles,
            ratio(uncollapsed)
        );
        for q in [&mut self.slack, &mut self.tight, &mut self.behind] {
            q.sort_by(f64::total_cmp);
        }
        let q = |v: &Vec<f64>, f: f64| v[((v.len().max(1) - 1) as f64 * f) as usize];
        println!(
            "  per-tile projected error / tau (tile error at its nearest sample): p10 {:.3} p50 {:.3} p90 {:.3} max {:.3}",
            q(&self.slack, 0.1),
            q(&self.slack, 0.5),
            q(&self.slack, 0.9),
            q(&self.slack, 1.0)
        );
        if !self.tight.is_empty() {
            println!(
                "  worst case's tightness (exact largest projected error / tile error at its nearest sample), {} tiles: p10 {:.3} p50 {:.3} p90 {:.3}; nearest distance / worst sample's distance: p10 {:.3} p50 {:.3} p90 {:.3}",
                self.tight.len(),
                q(&self.tight, 0.1),
                q(&self.tight, 0.5),
                q(&self.tight, 0.9),
                q(&self.behind, 0.1),
                q(&self.behind, 0.5),
                q(&self.behind, 0.9)
            );
        }
    }
}

/// A drawn tile's largest exact projected error (px: |level grid - sample| x focal / distance
/// over its full-resolution samples) and its nearest sample's distance over the distance of
/// the sample with the largest geometric error.
fn tile_exact(levels: &Levels, data: &Heightmap, cam: &Camera, focal: f64, t: Tile) -> (f64, f64) {
    let span = levels.grid_size << t.lod;
    let (c0, r0) = (t.x * span, t.y * span);
    let (c1, r1) = (
        (c0 + span).min(data.width - 1),
        (r0 + span).min(data.height - 1),
    );
    let (mut px, mut near, mut worst) = (0.0f64, f64::INFINITY, (0.0f64, f64::INFINITY));
    for r in r0..=r1 {
        for c in c0..=c1 {
            let h = data.sample(c, r) as f64;
            let dh = (levels::level_height(data, t.lod, c, r).unwrap() - h).abs();
            let pnt = glam::DVec3::new(c as f64 * data.spacing, r as f64 * data.spacing, h);
            let d = (pnt - cam.position).length();
            px = px.max(dh * focal / d);
            near = near.min(d);
            if dh > worst.0 {
                worst = (dh, d);
            }
        }
    }
    (px, near / worst.1)
}

/// Largest projected error of a drawn tile (its own geometric error at the nearest of its
/// samples) over tau.
fn tile_slack(
    levels: &Levels,
    data: &Heightmap,
    cam: &Camera,
    focal: f64,
    tau: f64,
    t: Tile,
) -> f64 {
    let span = levels.grid_size << t.lod;
    let (c0, r0) = (t.x * span, t.y * span);
    let (c1, r1) = (
        (c0 + span).min(data.width - 1),
        (r0 + span).min(data.height - 1),
    );
    let step = (1u32 << t.lod).max(1);
    let mut d = f64::INFINITY;
    let mut r = r0;
    while r <= r1 {
        let mut c = c0;
        while c <= c1 {
            let p = glam::DVec3::new(
                c as f64 * data.spacing,
                r as f64 * data.spacing,
                data.sample(c, r) as f64,
            );
            d = d.min((p - cam.position).length());
            c += step.min(span);
        }
        r += step.min(span);
    }
    levels.tile_error(t) as f64 * focal / d / tau
}

/// Counterfactual split rule: per-level corner values `s` (metres); a tile splits when its
/// nearest distance is below the largest of its corners.
struct SField {
    s: Vec<Vec<f64>>, // per level, (nx+1)*(ny+1)
}

#[derive(Clone, Copy)]
struct Cf {
    beta: f64,      // screen factor (1/(1-r) conservative, 1 linear blend)
    chain: bool,    // per-tile chain
    per_tile: bool, // per-tile error (else level max)
    cap: f64,       // s >= max/cap
    morph_range: f64,
    box_dist: bool, // tile box distance (else reference height)
    diam3d: bool,   // chain diameter includes the tile's height range
}

fn corner_idx(levels: &Levels, l: usize, i: u32, j: u32) -> usize {
    let (nx, _) = levels.tiles_per_side[l];
    (j * (nx + 1) + i) as usize
}

fn sfield(levels: &Levels, focal: f64, tau: f64, cf: Cf) -> SField {
    let keep = 1.0 - cf.morph_range;
    let mut s: Vec<Vec<f64>> = Vec::new();
    for l in 0..=levels.root_lod as usize {
        let (nx, ny) = levels.tiles_per_side[l];
        let mut v = vec![1e-3f64; ((nx + 1) * (ny + 1)) as usize];
        if l >= 1 {
            for ty in 0..ny {
                for tx in 0..nx {
                    let t = Tile {
                        x: tx,
                        y: ty,
                        lod: l as u32,
                    };
                    let e = if cf.per_tile {
                        levels.tile_error(t) as f64
                    } else {
                        levels.level_error[l]
                    };
                    let mut req = cf.beta * e * focal / tau;
                    if cf.chain && l >= 2 {
                        for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                            let c = Tile {
                                x: tx * 2 + dx,
                                y: ty * 2 + dy,
                                lod: l as u32 - 1,
                            };
                            if !levels.inside(c) {
                                continue;
                            }
                            let fine = &s[l - 1];
                            let mx = [(0, 0), (1, 0), (0, 1), (1, 1)]
                                .iter()
                                .map(|&(i, j)| fine[corner_idx(levels, l - 1, c.x + i, c.y + j)])
                                .fold(0.0, f64::max);
                            let ext = levels.tile_extent(l as u32 - 1);
                            let diam = if cf.diam3d {
                                let [lo, hi] = levels.tile_min_max(c);
                                (2.0 * ext * ext + ((hi - lo) as f64).powi(2)).sqrt()
                            } else {
                                std::f64::consts::SQRT_2 * ext
                            };
                            req = req.max((mx + diam) / keep);
                        }
                    }
                    for (i, j) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        let k = corner_idx(levels, l, tx + i, ty + j);
                        v[k] = v[k].max(req);
                    }
                }
            }
            let mx = v.iter().copied().fold(0.0, f64::max);
            for x in v.iter_mut() {
                *x = x.max(mx / cf.cap);
            }
        }
        s.push(v);
    }
    SField { s }
}

fn box_distance(levels: &Levels, cam: &Camera, t: Tile) -> f64 {
    let span = (levels.grid_size << t.lod) as f64 * levels.spacing;
    let [lo, hi] = levels.tile_min_max(t);
    let mn = glam::DVec3::new(t.x as f64 * span, t.y as f64 * span, lo as f64);
    let mx = glam::DVec3::new(
        ((t.x + 1) as f64 * span).min((levels.width - 1) as f64 * levels.spacing),
        ((t.y + 1) as f64 * span).min((levels.height - 1) as f64 * levels.spacing),
        hi as f64,
    );
    (cam.position.clamp(mn, mx) - cam.position).length()
}

/// Whether tile `t` splits under the counterfactual field `f`: its nearest distance (`Cf`'s
/// kind) below the largest of its corners.
fn cf_splits(
    levels: &Levels,
    p: &SelectionParams,
    cam: &Camera,
    f: &SField,
    cf: Cf,
    t: Tile,
) -> bool {
    let l = t.lod as usize;
    let mx = [(0, 0), (1, 0), (0, 1), (1, 1)]
        .iter()
        .map(|&(i, j)| f.s[l][corner_idx(levels, l, t.x + i, t.y + j)])
        .fold(0.0, f64::max);
    let d = if cf.box_dist {
        box_distance(levels, cam, t)
    } else {
        select::tile_distance(levels, p, t) as f64
    };
    d < mx
}

fn select_generic(
    levels: &Levels,
    p: &SelectionParams,
    splits: impl Fn(Tile) -> bool,
) -> Vec<Tile> {
    let mut out = Vec::new();
    let mut layer = vec![Tile {
        x: 0,
        y: 0,
        lod: levels.root_lod,
    }];
    while !layer.is_empty() {
        let mut next = Vec::new();
        for t in layer {
            if !levels.inside(t) || (p.cull && select::tile_culled(levels, p, t)) {
                continue;
            }
            if t.lod > 0 && splits(t) {
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

/// One frame's exact projected error test over full-resolution samples (the tile oracle's
/// and the quadrant oracle's).
struct ExactView<'a> {
    data: &'a Heightmap,
    cam: &'a Camera,
    focal: f64,
    tau: f64,
}

impl<'a> ExactView<'a> {
    fn new(data: &'a Heightmap, cam: &'a Camera, focal: f64, tau: f64) -> Self {
        ExactView {
            data,
            cam,
            focal,
            tau,
        }
    }

    /// Whether level `lod`'s triangulated grid is within tau (|grid - sample| x focal /
    /// distance) at every sample of the square of `span` quads from sample `origin` (clamped
    /// to the data).
    fn within_tau(&self, lod: u32, [c0, r0]: [u32; 2], span: u32) -> bool {
        let data = self.data;
        let (c1, r1) = (
            (c0 + span).min(data.width - 1),
            (r0 + span).min(data.height - 1),
        );
        (r0..=r1).all(|r| {
            (c0..=c1).all(|c| {
                let lh = levels::level_height(data, lod, c, r).unwrap();
                let h = data.sample(c, r) as f64;
                let pnt = glam::DVec3::new(c as f64 * data.spacing, r as f64 * data.spacing, h);
                (lh - h).abs() * self.focal <= self.tau * (pnt - self.cam.position).length()
            })
        })
    }

    /// Tile granularity limit: a tile splits iff some sample's projected error of the tile's
    /// level grid exceeds tau (no chain, no morph, no restriction).
    fn tile_splits(&self, levels: &Levels, t: Tile) -> bool {
        let span = levels.grid_size << t.lod;
        !self.within_tau(t.lod, [t.x * span, t.y * span], span)
    }

    /// Whether quadrant `q` (bit `qx + 2 qy`) of tile `t`, drawn as the parent level's grid,
    /// is within tau at every full-resolution sample it covers.
    fn quadrant_within_tau(&self, levels: &Levels, t: Tile, q: u32) -> bool {
        let span = levels.grid_size << t.lod;
        let half = span / 2;
        let (c0, r0) = (t.x * span + (q & 1) * half, t.y * span + (q >> 1) * half);
        if c0 > self.data.width - 1 || r0 > self.data.height - 1 {
            return true;
        }
        self.within_tau(t.lod + 1, [c0, r0], half)
    }
}

/// Counterfactual split field with nodes every `ns` quads of each level (no reach, zone or
/// cap; nesting and, with `ratio > 1`, a chamfer of `ratio` per node step): per level, node
/// values in metres, each the largest need of the cells around it.
fn cell_field(
    levels: &Levels,
    data: &Heightmap,
    scale: f64,
    ns: u32,
    ratio: f64,
) -> Vec<(Vec<f64>, (u32, u32))> {
    let mut out: Vec<(Vec<f64>, (u32, u32))> = Vec::new();
    for l in 0..=levels.root_lod {
        let step = ns << l;
        let ncx = (data.width - 1).div_ceil(step);
        let ncy = (data.height - 1).div_ceil(step);
        let (w1, h1) = (ncx + 1, ncy + 1);
        let mut nodes = vec![0.0f64; (w1 * h1) as usize];
        if l >= 1 {
            let mut need = vec![0.0f64; (ncx * ncy) as usize];
            for cy in 0..ncy {
                for cx in 0..ncx {
                    let mut e = 0.0f64;
                    for r in cy * step..=((cy + 1) * step).min(data.height - 1) {
                        for c in cx * step..=((cx + 1) * step).min(data.width - 1) {
                            let lh = levels::level_height(data, l, c, r).unwrap();
                            e = e.max((lh - data.sample(c, r) as f64).abs());
                        }
                    }
                    let mut v = e * scale;
                    {
                        // Nesting: no less than the level below anywhere in the cell.
                        let (fine, (fw, fh)) = &out[l as usize - 1];
                        for j in 2 * cy..=(2 * cy + 2).min(fh - 1) {
                            for i in 2 * cx..=(2 * cx + 2).min(fw - 1) {
                                v = v.max(fine[(j * fw + i) as usize]);
                            }
                        }
                    }
                    need[(cy * ncx + cx) as usize] = v;
                }
            }
            for cy in 0..ncy {
                for cx in 0..ncx {
                    let v = need[(cy * ncx + cx) as usize];
                    for (i, j) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        let k = ((cy + j) * w1 + cx + i) as usize;
                        nodes[k] = nodes[k].max(v);
                    }
                }
            }
            if ratio > 1.0 {
                for _ in 0..2 {
                    for k in 0..nodes.len() {
                        let (x, y) = ((k as u32 % w1) as i64, (k as u32 / w1) as i64);
                        for (ox, oy) in [
                            (-1i64, 0i64),
                            (1, 0),
                            (0, -1),
                            (0, 1),
                            (-1, -1),
                            (1, 1),
                            (-1, 1),
                            (1, -1),
                        ] {
                            let (sx, sy) = (x + ox, y + oy);
                            if sx >= 0 && sy >= 0 && sx < w1 as i64 && sy < h1 as i64 {
                                let n = nodes[(sy * w1 as i64 + sx) as usize] / ratio;
                                if n > nodes[k] {
                                    nodes[k] = n;
                                }
                            }
                        }
                    }
                }
            }
        }
        out.push((nodes, (w1, h1)));
    }
    out
}

/// `text` parsed as the value of `flag`, or an error naming both.
fn parse<T: std::str::FromStr>(flag: &str, text: &str) -> anyhow::Result<T>
where
    T::Err: std::fmt::Display,
{
    text.parse()
        .map_err(|e| anyhow::anyhow!("{flag} {text:?}: {e}"))
}

/// Triangles drawn, per [`CompletionTerms`], with the morph completing at a field below the
/// split field (`vkterrain::lod::udlod::completion`), over the frames' selections `views`
/// (the same tiles and quadrants outside the view as drawn today).
fn print_completion_counts(
    levels: &Levels,
    field: &SplitField,
    views: &[SelectionParams],
    tris_o: u64,
) {
    for terms in CompletionTerms::ALL {
        let completion = CompletionField::new(levels, field, terms);
        let tris: u64 = views
            .iter()
            .flat_map(|sp| {
                select::select_tiles(levels, sp)
                    .into_iter()
                    .map(move |t| (sp, t))
            })
            .map(|(sp, t)| {
                let collapsing = completion.tile_collapse_mask(levels, sp, t);
                let mask = TileMask::new(
                    levels.grid_size,
                    collapsing,
                    select::quadrants_culled(levels, sp, t),
                );
                grid::mask_triangles(levels.grid_size, mask)
            })
            .sum();
        println!(
            "  cf morph completing below the split field, {}: triangles {tris} ratio {:.2}",
            terms.name(),
            tris as f64 / tris_o as f64
        );
    }
}

/// Per level, how the field cells' own errors (`Levels::field_cell_error`, metres) spread:
/// the share exactly 0, the share under 1 cm, and quantiles. A data set's smooth filled voids
/// (SRTM's ocean) show as errors near, not at, 0.
fn print_cell_errors(levels: &Levels) {
    for lod in 1..=levels.root_lod {
        let (nx, ny) = levels.field_cells_per_side(lod);
        let mut e: Vec<f32> = (0..ny)
            .flat_map(|y| (0..nx).map(move |x| (x, y)))
            .map(|(x, y)| levels.field_cell_error(lod, x, y))
            .collect();
        e.sort_by(f32::total_cmp);
        let n = e.len();
        let share = |k: usize| 100.0 * k as f64 / n as f64;
        let q = |f: f64| e[((n - 1) as f64 * f) as usize];
        println!(
            "  cell errors level {lod}: {n} cells, 0 m {:.1} %, < 1 cm {:.1} %, p25 / p50 / p90 / max {:.3} / {:.3} / {:.3} / {:.3} m",
            share(e.iter().filter(|v| **v == 0.0).count()),
            share(e.iter().filter(|v| **v < 0.01).count()),
            q(0.25),
            q(0.5),
            q(0.9),
            q(1.0),
        );
    }
}

/// The prepass's seed for one frame (`seed::seed`, lists unbounded: no overflow): its tiles,
/// the GPU passes it leaves, and the host walk's median time over 200 runs (microseconds).
fn timed_seed(levels: &Levels, p: &SelectionParams, most: u32) -> (usize, u32, f64) {
    let lists = seed::ListCapacity {
        final_tiles: u32::MAX,
        temp_tiles: u32::MAX,
    };
    let mut times: Vec<f64> = (0..200)
        .map(|_| {
            let t0 = std::time::Instant::now();
            std::hint::black_box(seed::seed(levels, p, lists, most));
            t0.elapsed().as_secs_f64() * 1e6
        })
        .collect();
    times.sort_by(f64::total_cmp);
    let walk = seed::seed(levels, p, lists, most);
    (walk.tiles.len(), walk.passes, times[times.len() / 2])
}

/// One counterfactual's line: its tiles, their triangles and the ratio to the oracle's.
fn print_cf(name: &str, tiles: usize, triangles_per_tile: u64, oracle: u64) {
    let triangles = tiles as u64 * triangles_per_tile;
    println!(
        "  cf {name:48}: tiles {tiles:6} triangles {triangles:9} ratio {:.2}",
        triangles as f64 / oracle.max(1) as f64
    );
}

/// Counterfactual split test: the tile splits when some of its `sub` x `sub` sub-rectangles has
/// its nearest point nearer than the largest split distance at its corners (the field
/// bilinear over the sub-rectangle); `sub` = 1 is today's test.
fn sub_rect_splits(levels: &Levels, p: &SelectionParams, t: Tile, sub: u32) -> bool {
    let span = (levels.grid_size << t.lod) as i32;
    let step = span / sub as i32;
    let d_level = p.field.split[t.lod as usize];
    for j in 0..sub as i32 {
        for i in 0..sub as i32 {
            let c0 = [t.x as i32 * span + i * step, t.y as i32 * span + j * step];
            let c1 = [c0[0] + step, c0[1] + step];
            let m = [c0, [c1[0], c0[1]], [c0[0], c1[1]], c1]
                .map(|c| p.field.at(levels, c, t.lod))
                .into_iter()
                .fold(f32::INFINITY, f32::min);
            if m * select::rect_distance(p, c0, c1) < d_level {
                return true;
            }
        }
    }
    false
}
