//! Frame time of the default scenario at 1280x720 and 1920x1080 with 1 and 2 frames in
//! flight (the same code as `vkterrain bench`). Extra arguments for `vkterrain bench` can be
//! given in `VKTERRAIN_BENCH_ARGS`, e.g. `VKTERRAIN_BENCH_ARGS="--method brute --frames 100"`.
//! Results are also written to `target/bench/frame_time.json`.

use clap::Parser;
use vkterrain::cli::bench::{BenchArgs, run};

#[derive(Parser)]
#[command(args_override_self = true)]
struct Wrapper {
    #[command(flatten)]
    args: BenchArgs,
}

fn main() -> anyhow::Result<()> {
    let root = env!("CARGO_MANIFEST_DIR");
    let config = format!("{root}/config/default.toml");
    let json = format!("{root}/target/bench/frame_time.json");
    std::fs::create_dir_all(format!("{root}/target/bench"))?;
    let mut argv: Vec<String> = [
        "frame_time",
        "--config",
        &config,
        "--frames",
        "60",
        "--warmup",
        "10",
        "--json",
        &json,
    ]
    .map(String::from)
    .to_vec();
    if let Ok(extra) = std::env::var("VKTERRAIN_BENCH_ARGS") {
        argv.extend(extra.split_whitespace().map(String::from));
    }
    let w = Wrapper::try_parse_from(argv)?;
    run(&w.args)
}
