//! `vkterrain preprocess`: build a chunked-clipmap data set directory.

use std::path::PathBuf;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use crate::dataset::preprocess::{self, Input, Options, Progress};
use crate::dataset::procedural::{ProceduralParams, Style};

#[derive(Args, Debug)]
pub struct PreprocessArgs {
    /// DEM inputs: SRTM .hgt/.hgt.zip tiles (one mosaic), one GeoTIFF, or one 16-bit PNG.
    #[arg(required_unless_present = "procedural")]
    pub inputs: Vec<PathBuf>,
    /// Output data set directory (written atomically via `<out>.partial`).
    #[arg(long)]
    pub out: PathBuf,
    /// RGB(A) imagery (PNG/JPEG) covering the DEM, stored as the albedo layer.
    #[arg(long)]
    pub albedo: Option<PathBuf>,
    /// Metres between samples (needed for PNG; overrides georeferencing otherwise).
    #[arg(long)]
    pub spacing: Option<f64>,
    /// Metres per stored unit (PNG; multiplies other sources too).
    #[arg(long)]
    pub vertical_scale: Option<f64>,
    /// Generate procedural terrain instead of reading inputs.
    #[arg(long, conflicts_with = "inputs")]
    pub procedural: bool,
    /// Procedural: samples per side.
    #[arg(long, default_value_t = 4097)]
    pub size: u32,
    /// Procedural: height of the tallest possible peak, metres.
    #[arg(long, default_value_t = ProceduralParams::default().max_height)]
    pub max_height: f64,
    /// Procedural: wavelength of the largest features, metres.
    #[arg(long, default_value_t = ProceduralParams::default().feature_size)]
    pub feature_size: f64,
    /// Procedural: the terrain's character.
    #[arg(long, value_enum, default_value = "classic")]
    pub style: Style,
    /// Procedural (and --amplify): seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Amplify a real DEM by this factor with procedural detail below its resolution.
    #[arg(long)]
    pub amplify: Option<u32>,
    /// Centre texels per node side (even).
    #[arg(long, default_value_t = 256)]
    pub node_size: u32,
    /// Duplicated border texels per side (>= 2).
    #[arg(long, default_value_t = 2)]
    pub border: u32,
    /// Replace an existing data set at --out.
    #[arg(long)]
    pub force: bool,
}

struct Bars {
    bar: Option<ProgressBar>,
}

impl Progress for Bars {
    fn stage(&mut self, what: &str) {
        eprintln!("{what}...");
    }
    fn level(&mut self, lod: u32, nodes: u64) {
        let bar = ProgressBar::new(nodes);
        bar.set_style(
            ProgressStyle::with_template("level {msg:>3} [{bar:40}] {pos}/{len} nodes {eta}")
                .expect("valid template")
                .progress_chars("=> "),
        );
        bar.set_message(lod.to_string());
        self.bar = Some(bar);
    }
    fn advance(&mut self, n: u64) {
        if let Some(b) = &self.bar {
            b.inc(n);
        }
    }
    fn level_done(&mut self) {
        if let Some(b) = self.bar.take() {
            b.finish();
        }
    }
}

pub fn run(args: &PreprocessArgs) -> anyhow::Result<()> {
    if !(args.max_height.is_finite() && args.max_height > 0.0 && args.max_height <= 20_000.0) {
        anyhow::bail!("--max-height {} m is outside (0, 20000]", args.max_height);
    }
    if !(args.feature_size.is_finite() && (1.0..=1e7).contains(&args.feature_size)) {
        anyhow::bail!("--feature-size {} m is outside 1..=1e7", args.feature_size);
    }
    let input = if args.procedural {
        Input::Procedural(ProceduralParams {
            size: args.size,
            seed: args.seed,
            spacing: args.spacing.unwrap_or(ProceduralParams::default().spacing),
            max_height: args.max_height,
            feature_size: args.feature_size,
            style: args.style,
        })
    } else {
        Input::Files(args.inputs.clone())
    };
    let opts = Options {
        input,
        out: args.out.clone(),
        albedo: args.albedo.clone(),
        spacing: args.spacing,
        vertical_scale: args.vertical_scale,
        center_size: args.node_size,
        border_size: args.border,
        amplify: args.amplify.map(|k| (k, args.seed)),
        force: args.force,
    };
    let s = preprocess::run(&opts, &mut Bars { bar: None })?;
    println!("data set   {}", s.out.display());
    println!("source     {} [{}]", s.name, s.content);
    println!("samples    {}x{}", s.width, s.height);
    println!(
        "heights    {:.1} .. {:.1} m",
        s.height_range[0], s.height_range[1]
    );
    println!("levels     {}", s.levels);
    println!("nodes      {}", s.nodes);
    println!(
        "bytes      {} ({:.1} MiB)",
        s.bytes,
        s.bytes as f64 / 1048576.0
    );
    println!("voids      {} filled", s.voids_filled);
    println!(
        "time       {:.2} s ({:.1} source MB/s)",
        s.seconds,
        s.source_bytes as f64 / 1e6 / s.seconds.max(1e-9)
    );
    Ok(())
}
