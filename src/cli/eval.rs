//! `vkterrain eval`: a scenario rendered by several methods over parameter sweeps, measured on
//! the GPU against the exact surface; writes results.json, CSV, charts, images and report.md.
//! Any configuration the renderer draws is evaluable: one texture or the clipmap, several
//! views.

use std::path::PathBuf;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use crate::eval::report;
use crate::eval::run::{EvalSetup, Evaluation, Progress, evaluate, variants};
use crate::lod::MethodKind;

#[derive(Args, Debug, Clone)]
pub struct EvalArgs {
    #[command(flatten)]
    pub render: super::render::RenderArgs,
    /// Methods to evaluate, comma-separated.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "brute,udlod")]
    pub methods: Vec<MethodKind>,
    #[arg(long, help = crate::lod::sweep_help())]
    pub sweep: Vec<String>,
    /// Replace an existing output directory.
    #[arg(long)]
    pub force: bool,
    /// Frames written as side-by-side images (reference | method | error); negative counts
    /// from the end.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, default_values_t = [0i64, -1])]
    pub images: Vec<i64>,
    /// FLIP of every Nth measured frame (on the CPU, in parallel with the rendering; the image
    /// frames always); 0: the image frames only.
    #[arg(long, default_value_t = 16)]
    pub flip_every: u32,
    /// Also measure every frame on the CPU from read-back depth and fail unless both agree
    /// (slow: checks the GPU metrics on this device).
    #[arg(long)]
    pub cross_check: bool,
    /// Most memory (MiB) for the level-0 reference tiles around the views.
    #[arg(long, default_value_t = 512)]
    pub reference_mib: u64,
}

struct Bars(Option<ProgressBar>);

impl Progress for Bars {
    fn start(&mut self, label: &str, frames: u64) {
        let bar = ProgressBar::new(frames);
        bar.set_style(
            ProgressStyle::with_template("{msg:>32} [{bar:30}] {pos}/{len} frames {elapsed}")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar.set_message(label.to_string());
        self.0 = Some(bar);
    }
    fn advance(&mut self) {
        if let Some(b) = &self.0 {
            b.inc(1);
        }
    }
    fn finish(&mut self) {
        if let Some(b) = self.0.take() {
            b.finish();
        }
    }
}

pub fn run(args: &EvalArgs) -> anyhow::Result<()> {
    // On the configured earth (`[render] earth`, `--earth`): docs/eval.md, "On the earth".
    let p = super::render::prepare(&args.render)?;
    if args.methods.is_empty() {
        anyhow::bail!("--methods lists no method");
    }
    if args.reference_mib == 0 {
        anyhow::bail!("--reference-mib must be at least 1");
    }
    let sweeps = args
        .sweep
        .iter()
        .map(|s| crate::lod::sweep::parse(s))
        .collect::<crate::Result<Vec<_>>>()?;
    let variants = variants(&args.methods, &sweeps, &p.config.method)?;
    let out = args
        .render
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out/eval"));
    if out.exists() && !args.force {
        anyhow::bail!("{}: exists (use --force to replace it)", out.display());
    }
    let gpu = p.config.open_gpu()?;
    let warmup = args.render.warmup.min(p.frames.saturating_sub(2) as usize);
    let setup = EvalSetup {
        gpu: &gpu,
        config: &p.config,
        data: &p.data,
        scenario: &p.scenario,
        frames: p.frames,
        warmup,
        options: p.config.render_options(),
        image_frames: super::render::png_frames(&args.images, p.frames),
        flip_every: args.flip_every,
        cross_check: args.cross_check,
        reference_mib: args.reference_mib,
        command: command_line(),
    };
    print_start(&setup, &p, variants.len());
    let evaluation = evaluate(&setup, &variants, &mut Bars(None))?;
    super::render::check_validation(&gpu)?;
    require_cross_check(&evaluation)?;
    report::write(&evaluation, &out, args.force)?;
    print_results(&evaluation, &out);
    Ok(())
}

/// What is about to be evaluated, on standard error.
fn print_start(setup: &EvalSetup, p: &super::render::Prepared, variants: usize) {
    eprintln!(
        "eval: {variants} variants + reference, {} frames of {} on {} at {}x{} ({} view(s){}), device {}",
        p.frames,
        p.scenario.name,
        p.data.name(),
        setup.options.width,
        setup.options.height,
        setup.options.views,
        if p.config.clipmap.enabled {
            ", clipmap"
        } else {
            ""
        },
        setup.gpu.info.name
    );
}

/// With `--cross-check`: an error (and the first 20 places) wherever the GPU's metrics and
/// the CPU path's differ; nothing is written then.
fn require_cross_check(evaluation: &Evaluation) -> anyhow::Result<()> {
    if let Some(check) = &evaluation.cross_check
        && let Some(first) = check.problems.first()
    {
        for p in check.problems.iter().take(20) {
            eprintln!("cross-check: {p}");
        }
        anyhow::bail!(
            "cross-check: GPU and CPU metrics differ in {} place(s); first: {first}",
            check.problems.len()
        );
    }
    Ok(())
}

/// The summary table, the budget warnings and where the report went.
fn print_results(evaluation: &Evaluation, out: &std::path::Path) {
    print!(
        "{}",
        crate::eval::table::text(crate::eval::table::SUMMARY_COLUMNS, &evaluation.summaries)
    );
    for w in crate::eval::budget_warnings(&evaluation.summaries) {
        eprintln!("warning: {w}");
    }
    if let Some(check) = &evaluation.cross_check {
        println!(
            "cross-check: GPU metrics equal the CPU path's on {} frames",
            check.frames
        );
    }
    println!(
        "evaluated in {:.1} s; wrote {}/report.md",
        evaluation.wall_s,
        out.display()
    );
}

/// This process's command line, quoted for a POSIX shell.
fn command_line() -> String {
    std::env::args()
        .enumerate()
        .map(|(i, a)| {
            let a = if i == 0 { "vkterrain".to_string() } else { a };
            if !a.is_empty()
                && a.chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_./=,:@+".contains(c))
            {
                a
            } else {
                format!("'{}'", a.replace('\'', "'\\''"))
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}
