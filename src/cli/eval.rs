//! `vkterrain eval`: a scenario rendered by several methods over parameter sweeps, measured
//! against the exact surface; writes results.json, CSV, charts, images and report.md.

use std::path::PathBuf;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use crate::eval::report;
use crate::eval::run::{EvalSetup, Progress, evaluate, variants};
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
    let p = super::render::prepare(&args.render)?;
    let methods = &args.methods;
    if methods.is_empty() {
        anyhow::bail!("--methods lists no method");
    }
    if !p.config.render.extra_views.is_empty() {
        // The metrics reconstruct world positions from one camera per image.
        anyhow::bail!(
            "render.extra_views: eval compares one camera per frame; remove the extra views"
        );
    }
    let sweeps = args
        .sweep
        .iter()
        .map(|s| crate::lod::sweep::parse(s))
        .collect::<crate::Result<Vec<_>>>()?;
    let variants = variants(methods, &sweeps, &p.config.method)?;
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
    let data = p.data.require_grid("eval (exact-surface metrics)")?;
    let setup = EvalSetup {
        gpu: &gpu,
        data,
        scenario: &p.scenario,
        frames: p.frames,
        warmup,
        options: p.config.render_options(),
        image_frames: super::render::png_frames(&args.images, p.frames),
    };
    eprintln!(
        "eval: {} variants + reference, {} frames of {} on {} at {}x{}, device {}",
        variants.len(),
        p.frames,
        p.scenario.name,
        data.name,
        setup.options.width,
        setup.options.height,
        gpu.info.name
    );
    let evaluation = evaluate(&setup, &variants, &mut Bars(None))?;
    super::render::check_validation(&gpu)?;
    report::write(&evaluation, data, &out, args.force)?;
    print!(
        "{}",
        crate::eval::table::text(crate::eval::table::SUMMARY_COLUMNS, &evaluation.summaries)
    );
    println!("wrote {}/report.md", out.display());
    Ok(())
}
