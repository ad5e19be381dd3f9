//! The `vkterrain` command line: `info`, `render`, `bench`, `preprocess`, `serve`, `status`
//! and (with Zenoh) `subscribe`.

pub mod bench;
pub mod eval;
pub mod info;
pub mod preprocess;
pub mod render;
pub mod serve;
#[cfg(feature = "zenoh")]
pub mod subscribe;

use std::path::PathBuf;

use clap::{Parser, Subcommand};

#[derive(Parser, Debug)]
#[command(
    name = "vkterrain",
    version,
    about = "Headless Vulkan terrain renderer"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Print the chosen Vulkan device, its memory and the features vkterrain uses or could use.
    Info {
        /// Configuration file (TOML); built-in defaults without one.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Device override: index or name substring (VKTERRAIN_DEVICE also works).
        #[arg(long)]
        device: Option<String>,
    },
    /// Render a scenario headless, write selected frames as PNG and print a summary.
    Render(render::RenderArgs),
    /// Frame-time benchmark: the scenario at several resolutions and frames-in-flight counts.
    Bench(bench::BenchArgs),
    /// Evaluate methods over a scenario against the exact surface: tables, charts, images.
    Eval(eval::EvalArgs),
    /// Build a chunked-clipmap data set (node pyramid + manifest) from DEMs or procedurally.
    Preprocess(preprocess::PreprocessArgs),
    /// Headless service: render until SIGTERM/SIGINT, publishing every frame into the
    /// shared-memory ring; camera from the scenario or the control socket.
    Serve(serve::ServeArgs),
    /// Print the status file of a running `serve` and/or a ring's header.
    Status(serve::StatusArgs),
    /// Receive `serve`'s frames over Zenoh (print metadata, save PNG), send it control
    /// messages, or query its status.
    #[cfg(feature = "zenoh")]
    Subscribe(subscribe::SubscribeArgs),
}

/// Runs the parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Info { config, device } => info::run(config.as_deref(), device),
        Command::Render(args) => render::run(&args),
        Command::Bench(args) => bench::run(&args),
        Command::Preprocess(args) => preprocess::run(&args),
        Command::Eval(args) => eval::run(&args),
        Command::Serve(args) => serve::run(&args),
        Command::Status(args) => serve::status(&args),
        #[cfg(feature = "zenoh")]
        Command::Subscribe(args) => subscribe::run(&args),
    }
}
