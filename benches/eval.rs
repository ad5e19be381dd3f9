//! Speed against accuracy on lavapipe (or any device): brute force, UDLOD at tau 0.5/1/2/4 and
//! PGM at two grid sizes over scenarios, each written as a full evaluation (`report.md`,
//! charts, CSV, images) under `target/bench/eval/<name>/` and summarised in
//! `target/bench/eval.json`.
//!
//! Each case is evaluated on its configured earth (`[render] earth`: a data set with a world
//! frame on the ellipsoid by default, where PGM is not run yet: see `run_case`).
//!
//! `VKTERRAIN_EVAL_SHORT=1` is the CI version (the procedural CI terrain at 320x180, flat and
//! anchored on the earth, a few minutes at most). It asserts correctness, never absolute times:
//! UDLOD has no cracks (sky seen through its surface), few sky pixels under a lowered
//! silhouette and its skyline no more than 2 tau + 1 px lower, its 99.9th-percentile
//! screen-space error is within 1.25 tau and over the pixels it draws coarser than level 0 in
//! [0.5, 1.25] tau (it spends tau), brute force measures ~0 error, and PGM swims more
//! than UDLOD per pixel of error; GPU times are printed as ratios to brute force of the same
//! run; and the evaluator's GPU time of each method agrees with a plain benchmark loop's (the
//! `vkterrain bench` loop, no evaluation) as a ratio within a generous noise band. Without it,
//! the Fischer flights S1 (Franconia, flat) and S3 (Pyrenees, rough) run at 1280x720 (data:
//! `make data`).

use std::path::PathBuf;

use clap::Parser;
use vkterrain::cli::render::{Prepared, RenderArgs, prepare};
use vkterrain::eval::metrics::Holes;
use vkterrain::eval::run::{EvalSetup, Evaluation, Variant, evaluate, variants};
use vkterrain::eval::{report, table};
use vkterrain::lod::{MethodConfig, MethodKind, sweep};
use vkterrain::render::FrameRequest;
use vkterrain::render::stats::Percentiles;

/// The evaluator's GPU time may differ from the benchmark loop's by this factor either way
/// (the machines are noisy: the same command runs up to 1.7x apart). On lavapipe at 320x180
/// eval read 0.58-1.12 of the bench loop's time over four runs, usually below it (not
/// explained yet, docs/eval.md); the band still fails the 5x the issue measured.
const AGREEMENT_BAND: f64 = 2.0;
/// Measurements of a case before a disagreement fails the bench (`run_until_agreement`).
const AGREEMENT_ATTEMPTS: usize = 3;

#[derive(Parser)]
struct Wrapper {
    #[command(flatten)]
    args: RenderArgs,
}

struct Case {
    name: &'static str,
    config: &'static str,
    scenario: Option<&'static str>,
    frames: u32,
    size: (u32, u32),
}

/// GPU time per frame of the method's passes (prepass + terrain, median after warm-up) in the
/// `vkterrain bench` loop: a sink that reads every row, no evaluation, one frame in flight
/// like the evaluator (`vkterrain bench`'s N = 1 row). With two frames in flight the frames
/// overlap, and on lavapipe both share the same CPU cores, so each frame's GPU interval grows
/// (UDLOD at 720p: 407 ms at N = 1, 662 ms at N = 2 in one `vkterrain bench` run).
fn bench_gpu_ms(p: &Prepared, method: &MethodConfig, warmup: usize) -> anyhow::Result<f64> {
    let gpu = p.config.open_gpu()?;
    let mut config = p.config.clone();
    config.method = method.clone();
    let mut options = config.render_options();
    options.frames_in_flight = 1;
    let mut renderer = config.open_renderer(&gpu, &p.data, options)?;
    let mut checksum = 0u64;
    let mut sink = |f: &vkterrain::readback::FrameView<'_>| {
        checksum = checksum.wrapping_add(f.rgba.chunks(f.row_stride).map(|r| r[0] as u64).sum());
        Ok(())
    };
    for frame in 0..p.frames as u64 {
        let views =
            FrameRequest::with_extra_views(p.scenario.camera(frame), &config.render.extra_views);
        renderer.render_views(&views, &mut sink)?;
    }
    renderer.finish(&mut sink)?;
    let times = renderer
        .stats
        .frames
        .iter()
        .skip(warmup)
        .map(|f| f.timings.gpu_prepass_ms + f.timings.gpu_terrain_ms)
        .collect();
    Ok(Percentiles::of(times).median)
}

/// Eval and bench agree on every method's GPU time within [`AGREEMENT_BAND`].
fn check_agreement(p: &Prepared, evaluation: &Evaluation, warmup: usize) -> anyhow::Result<()> {
    let mut failures = Vec::new();
    for s in evaluation
        .summaries
        .iter()
        .filter(|s| s.method == "brute" || s.method == "pgm" || s.variant == "udlod tau_px=1")
    {
        let mut method = p
            .config
            .method
            .clone()
            .with_kind(MethodKind::parse(&s.method)?);
        for (k, v) in &s.params {
            method.apply_sweep(k, *v)?;
        }
        let bench = bench_gpu_ms(p, &method, warmup)?;
        let ratio = s.gpu_ms.median / bench;
        println!(
            "{}: eval {:.3} ms, bench {:.3} ms: ratio {ratio:.2}",
            s.variant, s.gpu_ms.median, bench
        );
        if !(1.0 / AGREEMENT_BAND..=AGREEMENT_BAND).contains(&ratio) {
            failures.push(format!("{} ratio {ratio:.2}", s.variant));
        }
    }
    if failures.is_empty() {
        println!("eval and bench agree within {AGREEMENT_BAND}x");
        Ok(())
    } else {
        Err(Disagreement(failures.join("; ")).into())
    }
}

/// Runs a case; a disagreement of eval and bench is measured again, up to
/// [`AGREEMENT_ATTEMPTS`] times, and fails only if every attempt disagrees. Lavapipe's GPU times
/// on a shared 2-core machine jump for seconds at a time (one run measured a variant's eval
/// median at 5.3x its bench median, the next 1.04x; brute force once 2.68x and then 0.46x,
/// the other way round), while an evaluator that times its own work would disagree the same
/// way every time.
fn run_until_agreement(root: &str, case: &Case, short: bool) -> anyhow::Result<Option<Evaluation>> {
    let mut attempt = 1;
    loop {
        match run_case(root, case, short) {
            Err(e)
                if e.downcast_ref::<Disagreement>().is_some() && attempt < AGREEMENT_ATTEMPTS =>
            {
                println!(
                    "{e}; measuring {} again (attempt {} of {AGREEMENT_ATTEMPTS})",
                    case.name,
                    attempt + 1
                );
                attempt += 1;
            }
            other => return other,
        }
    }
}

/// Eval and bench GPU times outside [`AGREEMENT_BAND`] (the variants and their ratios).
#[derive(Debug)]
struct Disagreement(String);

impl std::fmt::Display for Disagreement {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "eval and bench GPU times differ by more than {AGREEMENT_BAND}x: {}",
            self.0
        )
    }
}

impl std::error::Error for Disagreement {}

fn run_case(root: &str, case: &Case, short: bool) -> anyhow::Result<Option<Evaluation>> {
    let Some(p) = prepare_case(root, case)? else {
        return Ok(None);
    };
    let gpu = p.config.open_gpu()?;
    let variants = case_variants(&p, case.name)?;
    let warmup = 4;
    let command = format!(
        "{}cargo bench --bench eval",
        if short { "VKTERRAIN_EVAL_SHORT=1 " } else { "" }
    );
    let setup = EvalSetup {
        gpu: &gpu,
        config: &p.config,
        data: &p.data,
        scenario: &p.scenario,
        frames: p.frames,
        warmup,
        options: p.config.render_options(),
        image_frames: vec![p.frames as u64 / 2],
        flip_every: 8,
        cross_check: false,
        reference_mib: 512,
        command,
    };
    let evaluation = evaluate(&setup, &variants, &mut ())?;
    let out = PathBuf::from(format!("{root}/target/bench/eval/{}", case.name));
    report::write(&evaluation, &out, true)?;
    print_case(case, &evaluation, &out);
    if short {
        check_agreement(&p, &evaluation, warmup)?;
    }
    Ok(Some(evaluation))
}

/// The case's config, scenario, frames and size as `vkterrain eval` would read them (the
/// configured earth: the same scenario cameras, the same geometry); `None` (with a line
/// saying why) when its data set is missing.
fn prepare_case(root: &str, case: &Case) -> anyhow::Result<Option<Prepared>> {
    let mut argv = vec![
        "eval".to_string(),
        "--config".into(),
        format!("{root}/{}", case.config),
        "--frames".into(),
        case.frames.to_string(),
        "--width".into(),
        case.size.0.to_string(),
        "--height".into(),
        case.size.1.to_string(),
    ];
    if let Some(s) = case.scenario {
        argv.extend(["--scenario".into(), format!("{root}/{s}")]);
    }
    let args = Wrapper::try_parse_from(argv)?.args;
    match prepare(&args) {
        Ok(p) => Ok(Some(p)),
        Err(e) => {
            println!(
                "skipping {}: {e:#} (make data builds the data sets)",
                case.name
            );
            Ok(None)
        }
    }
}

/// Brute force, UDLOD and PGM over tau 0.5-4, PGM's grid at two scales. On the ellipsoid
/// the case compares brute force and UDLOD: PGM draws on the earth since its grid meets the
/// curved surface (docs/pgm.md, "On the earth"), but its earth cases (CI time, the swimming
/// assertion there) are not added yet.
fn case_variants(p: &Prepared, name: &str) -> anyhow::Result<Vec<Variant>> {
    let on_earth = p.config.render.earth == vkterrain::render::EarthGeometry::Ellipsoid
        && p.config.world_frame()?.is_some();
    let methods: &[MethodKind] = if on_earth {
        println!("{name}: on the ellipsoid, without PGM (flat only)");
        &[MethodKind::Brute, MethodKind::Udlod]
    } else {
        &[MethodKind::Brute, MethodKind::Udlod, MethodKind::Pgm]
    };
    let mut sweeps = vec![sweep::parse("tau_px=0.5,1,2,4")?];
    if !on_earth {
        sweeps.push(sweep::parse("grid_scale=0.5,1")?);
    }
    Ok(variants(methods, &sweeps, &p.config.method)?)
}

/// The case's summary table, and each variant's GPU time as a ratio to brute force's of the
/// same run (the machines are noisy; absolute times drift between runs).
fn print_case(case: &Case, evaluation: &Evaluation, out: &std::path::Path) {
    let brute = evaluation
        .summaries
        .iter()
        .find(|s| s.method == "brute")
        .map(|s| s.gpu_ms.median)
        .unwrap_or(f64::NAN);
    println!(
        "\n{} ({} on {}, {}x{}, {} frames, {}, {:.1} s) -> {}/report.md",
        case.name,
        evaluation.scenario,
        evaluation.dataset,
        evaluation.width,
        evaluation.height,
        evaluation.frames,
        evaluation.device,
        evaluation.wall_s,
        out.display()
    );
    print!(
        "{}",
        table::text(table::SUMMARY_COLUMNS, &evaluation.summaries)
    );
    let ratios: Vec<String> = evaluation
        .summaries
        .iter()
        .map(|s| format!("{} {:.2}", s.variant, s.gpu_ms.median / brute))
        .collect();
    println!("median GPU time / brute force's: {}", ratios.join(", "));
}

/// Mean swimming (px) per pixel of p99.9 error: how much of a method's error moves with the
/// camera. UDLOD's error is fixed to the terrain (it moves only while a tile morphs); PGM's
/// grid is fixed to the screen, so its error slides over the terrain. Since issue 18 UDLOD
/// spends its error budget (larger error, so more absolute swimming than the finer PGM grids
/// of this short run); compared per pixel of error the two methods differ as the papers say.
fn swim_share(s: &vkterrain::eval::run::RunSummary) -> f64 {
    s.swimming_px.mean / s.error.pixels.p999.max(1e-6)
}

/// Where its pixels are drawn coarser than level 0 (`eval::coarse`), UDLOD spends tau (issue
/// 18): their 99.9th percentile lies in [0.5, 1.25] tau (the band, with the error bound's
/// tolerance above it), checked where they are at least this share of the pixels.
const SPENDING_SHARE: f64 = 0.1;

fn spends_tau(s: &vkterrain::eval::run::RunSummary, tau: f64) -> Option<String> {
    let Some(c) = s.coarse else {
        return Some(format!("{}: coarse pixels not measured", s.variant));
    };
    let ratio = c.p999_px / tau;
    (c.share >= SPENDING_SHARE && !(0.5..=1.25).contains(&ratio)).then(|| {
        format!(
            "{}: coarse pixels' p99.9 {:.3} px = {ratio:.2} tau, outside [0.5, 1.25] tau",
            s.variant, c.p999_px
        )
    })
}

/// Correctness of the short run: the assertions CI makes.
fn check(evaluation: &Evaluation) -> anyhow::Result<()> {
    let mut failures = Vec::new();
    let mut udlod_swim = 0.0f64;
    let mut pgm_swim = f64::INFINITY;
    for s in &evaluation.summaries {
        match s.method.as_str() {
            "brute" if s.error.pixels.p999 > 0.01 => {
                failures.push(format!("brute force error {} px", s.error.pixels.p999))
            }
            "udlod" => {
                let tau = s
                    .params
                    .iter()
                    .find(|(k, _)| k == "tau_px")
                    .map_or(1.0, |p| p.1);
                if s.cracks_total > 0 {
                    failures.push(format!("{}: {} cracks", s.variant, s.cracks_total));
                }
                if f64::from(s.silhouette_px_max) > Holes::allowed_fall_px(tau) {
                    failures.push(format!(
                        "{}: skyline {} px below the reference's",
                        s.variant, s.silhouette_px_max
                    ));
                }
                let silhouette = s.holes_total - s.cracks_total;
                if silhouette > Holes::allowed_silhouette_pixels(s.frames, evaluation.width) {
                    failures.push(format!(
                        "{}: {silhouette} sky pixels under a lowered silhouette",
                        s.variant
                    ));
                }
                if s.error.pixels.p999 > 1.25 * tau {
                    failures.push(format!(
                        "{}: error {} px > 1.25 tau",
                        s.variant, s.error.pixels.p999
                    ));
                }
                failures.extend(spends_tau(s, tau));
                udlod_swim = udlod_swim.max(swim_share(s));
            }
            "pgm" => pgm_swim = pgm_swim.min(swim_share(s)),
            _ => {}
        }
    }
    let has_pgm = evaluation.summaries.iter().any(|s| s.method == "pgm");
    if has_pgm && pgm_swim <= udlod_swim {
        failures.push(format!(
            "PGM swims {pgm_swim} px per px of error, not more than UDLOD's {udlod_swim}"
        ));
    }
    if failures.is_empty() {
        if has_pgm {
            println!(
                "checks passed: UDLOD watertight, within tau and spending it, PGM swims {:.1}x more than UDLOD per px of error",
                pgm_swim / udlod_swim.max(1e-9)
            );
        } else {
            println!("checks passed: UDLOD watertight, within tau and spending it, brute force ~0");
        }
        Ok(())
    } else {
        anyhow::bail!("eval checks failed: {}", failures.join("; "))
    }
}

fn main() -> anyhow::Result<()> {
    let root = env!("CARGO_MANIFEST_DIR");
    let short = std::env::var("VKTERRAIN_EVAL_SHORT").is_ok_and(|v| v == "1");
    let cases: Vec<Case> = if short {
        vec![
            Case {
                name: "ci",
                config: "config/ci.toml",
                scenario: None,
                frames: 24,
                size: (320, 180),
            },
            // The same terrain anchored on the earth: drawn and evaluated on the ellipsoid.
            Case {
                name: "ci_earth",
                config: "config/ci_earth.toml",
                scenario: None,
                frames: 24,
                size: (320, 180),
            },
        ]
    } else {
        vec![
            Case {
                name: "fischer_s1_franconia",
                config: "config/franconia.toml",
                scenario: Some("config/scenarios/franconia_fischer_s1_flat_close_down63.toml"),
                frames: 48,
                size: (1280, 720),
            },
            Case {
                name: "fischer_s3_pyrenees",
                config: "config/pyrenees.toml",
                scenario: Some("config/scenarios/pyrenees_fischer_s3_rough_far_down45.toml"),
                frames: 48,
                size: (1280, 720),
            },
        ]
    };
    let mut all = Vec::new();
    for case in &cases {
        let evaluation = run_until_agreement(root, case, short)?;
        if let Some(e) = evaluation {
            if short {
                check(&e)?;
            }
            all.push(serde_json::json!({
                "case": case.name,
                "scenario": e.scenario,
                "dataset": e.dataset,
                "summaries": e.summaries,
            }));
        }
    }
    std::fs::create_dir_all(format!("{root}/target/bench"))?;
    std::fs::write(
        format!("{root}/target/bench/eval.json"),
        serde_json::to_string_pretty(&all)?,
    )?;
    Ok(())
}
