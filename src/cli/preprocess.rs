//! `vkterrain preprocess`: build a chunked-clipmap data set directory.

use std::path::PathBuf;
use std::sync::Mutex;

use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use crate::dataset::preprocess::{self, Input, Options, Progress};
use crate::dataset::procedural::{ProceduralParams, Style};
use crate::dataset::xyz::{Encoding, XyzSettings};

#[derive(Args, Debug)]
pub struct PreprocessArgs {
    /// DEM inputs, any raster GDAL reads (GeoTIFF/COG, SRTM .hgt/.hgt.zip, netCDF, VRT, IMG,
    /// JPEG2000, PNG, ...): one file, or several forming a mosaic.
    #[arg(required_unless_present_any = ["procedural", "xyz"])]
    pub inputs: Vec<PathBuf>,
    /// Output data set directory (written atomically via `<out>.partial`).
    #[arg(long)]
    pub out: PathBuf,
    /// RGB(A) imagery (PNG/JPEG) covering the DEM, stored as the albedo layer.
    #[arg(long)]
    pub albedo: Option<PathBuf>,
    /// Metres between samples (needed without georeferencing; overrides it otherwise).
    #[arg(long)]
    pub spacing: Option<f64>,
    /// Metres per stored unit (PNG; multiplies other sources too).
    #[arg(long)]
    pub vertical_scale: Option<f64>,
    /// Target CRS when inputs are warped into one mosaic (EPSG:xxxx, WKT or PROJ string;
    /// default: the first input's).
    #[arg(long)]
    pub crs: Option<String>,
    /// Datum of the heights when the source does not say: egm96, egm2008, ellipsoid, unknown.
    #[arg(long)]
    pub vertical_datum: Option<String>,
    /// Generate procedural terrain instead of reading inputs.
    #[arg(long, conflicts_with_all = ["inputs", "xyz"])]
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
    /// XYZ terrain tiles: `http(s)://.../{z}/{x}/{y}.png` or a directory of z/x/y.png.
    #[arg(long, conflicts_with = "inputs", requires_all = ["bbox", "zoom"])]
    pub xyz: Option<String>,
    /// XYZ: terrarium or mapbox (terrain-RGB).
    #[arg(long, default_value = "terrarium")]
    pub encoding: String,
    /// XYZ: west,south,east,north in degrees.
    #[arg(long, value_delimiter = ',', num_args = 4, allow_hyphen_values = true)]
    pub bbox: Option<Vec<f64>>,
    /// XYZ: zoom level.
    #[arg(long)]
    pub zoom: Option<u32>,
    /// XYZ: pixels per tile side (256 or 512).
    #[arg(long, default_value_t = 256)]
    pub tile_size: u32,
    /// XYZ (http): tile cache directory (default ~/.cache/vkterrain/xyz).
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
    /// Centre texels per node side (even).
    #[arg(long, default_value_t = 256)]
    pub node_size: u32,
    /// Duplicated border texels per side (>= 2).
    #[arg(long, default_value_t = 2)]
    pub border: u32,
    /// Tile sizes whose statistics are stored, comma-separated (default 2: the cells of UDLOD's
    /// default split field, grid 4 with two nodes per side; below 4 without level 0's tiles).
    #[arg(long, value_delimiter = ',', default_values_t = preprocess::DEFAULT_STATS_GRID_SIZES)]
    pub stats_grid_sizes: Vec<u32>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Replace an existing data set at --out (never anything that is not a data set).
    #[arg(long)]
    pub force: bool,
}

struct Bars {
    bar: Mutex<Option<ProgressBar>>,
}

impl Bars {
    fn with(&self, f: impl FnOnce(&mut Option<ProgressBar>)) {
        f(&mut self.bar.lock().unwrap_or_else(|e| e.into_inner()));
    }
}

impl Progress for Bars {
    fn stage(&self, what: &str) {
        eprintln!("{what}...");
    }
    fn level(&self, what: &str, total: u64) {
        let bar = ProgressBar::new(total);
        bar.set_style(
            ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} {eta}")
                .expect("valid template")
                .progress_chars("=> "),
        );
        bar.set_message(what.to_string());
        self.with(|b| *b = Some(bar));
    }
    fn advance(&self, n: u64) {
        self.with(|b| {
            if let Some(b) = b {
                b.inc(n);
            }
        });
    }
    fn level_done(&self) {
        self.with(|b| {
            if let Some(b) = b.take() {
                b.finish();
            }
        });
    }
    fn warning(&self, line: &str) {
        eprintln!("warning: {line}");
    }
}

fn options(args: &PreprocessArgs) -> anyhow::Result<Options> {
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
    } else if let Some(source) = &args.xyz {
        let b = args.bbox.clone().unwrap_or_default();
        let bbox: [f64; 4] = b
            .try_into()
            .map_err(|_| anyhow::anyhow!("--bbox needs west,south,east,north"))?;
        Input::Xyz(XyzSettings {
            source: source.clone(),
            encoding: Encoding::parse(&args.encoding)?,
            bbox,
            zoom: args.zoom.unwrap_or_default(),
            tile_size: args.tile_size,
            cache_dir: args.cache_dir.clone(),
            ..Default::default()
        })
    } else {
        Input::Files(args.inputs.clone())
    };
    Ok(Options {
        input,
        out: args.out.clone(),
        albedo: args.albedo.clone(),
        spacing: args.spacing,
        vertical_scale: args.vertical_scale,
        center_size: args.node_size,
        border_size: args.border,
        amplify: args.amplify.map(|k| (k, args.seed)),
        force: args.force,
        crs: args.crs.clone(),
        stats_grid_sizes: args.stats_grid_sizes.clone(),
        vertical_datum: args.vertical_datum.clone(),
        memory_budget: None,
    })
}

pub fn run(args: &PreprocessArgs) -> anyhow::Result<()> {
    let opts = options(args)?;
    let bars = Bars {
        bar: Mutex::new(None),
    };
    let s = match args.threads {
        Some(n) => rayon::ThreadPoolBuilder::new()
            .num_threads(n.max(1))
            .build()?
            .install(|| preprocess::run(&opts, &bars))?,
        None => preprocess::run(&opts, &bars)?,
    };
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
    println!("warnings   {}", s.warnings.len());
    // Procedural data has no source bytes: its rate is output samples per second.
    let secs = s.seconds.max(1e-9);
    let rate = if s.source_bytes > 0 {
        format!("{:.1} source MB/s", s.source_bytes as f64 / 1e6 / secs)
    } else {
        format!("{:.1} Msamples/s", (s.width * s.height) as f64 / 1e6 / secs)
    };
    println!(
        "time       {:.2} s ({rate}, {} threads)",
        s.seconds,
        rayon::current_num_threads().min(args.threads.unwrap_or(usize::MAX))
    );
    println!(
        "peak RSS   {:.1} MiB",
        crate::render::stats::peak_rss_bytes().unwrap_or(0) as f64 / 1048576.0
    );
    Ok(())
}
