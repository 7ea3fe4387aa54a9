//! Real faces the model never saw, with no monitor stream (the source light is
//! predicted): the element's output scored with measures that need no ground
//! truth (box edges, mottling, pumping; `lsydrelight_testkit::quality`), on
//! real footage and on the simulator's recordings (where the exact error is
//! given too), with a before/after image of each and a map of the change it
//! made. What is measured, and how, is `lsydrelight_testkit::scorecard`;
//! `cargo run --release --example benchmark -- --quality` writes the same
//! report, RGB and I420, into the benchmark's results.
//!
//! ```text
//! cargo run --release --example real_footage -- [--media target/real-media] [--out results/real] \
//!     [--frames 90] [--target models/targets/sunset.png] [--model models/starter] [--format RGB|I420] \
//!     [--denoise true|false] [--only cuts]...
//! ```
//!
//! The element runs with its defaults (`denoise` on unless `--denoise false`),
//! fed packed RGB or, as webcams deliver frames, I420. The model is the
//! element's default, the starter model for anyone, unless `--model` names
//! another. The real clips are fetched by `scripts/setup.sh full` into
//! `target/real-media`.

use std::path::PathBuf;

use clap::Parser;

use lsydrelight_testkit::{
    checkout,
    footage::Format,
    init,
    scorecard::{Setup, report},
};

/// Real faces with no monitor stream, scored with measures that need no ground truth.
#[derive(Parser)]
struct Args {
    /// The real portraits and clips (default: target/real-media, from set-up).
    #[arg(long)]
    media: Option<PathBuf>,
    /// Where the report and images go (default: results/real).
    #[arg(long)]
    out: Option<PathBuf>,
    /// The target light image (default: models/targets/sunset.png).
    #[arg(long)]
    target: Option<PathBuf>,
    /// The model folder (default: the element's default model).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Frames of each clip.
    #[arg(long, default_value_t = 90)]
    frames: usize,
    /// The format fed to the element: RGB or I420.
    #[arg(long, default_value = "RGB", value_parser = Format::parse)]
    format: Format,
    /// The element's `denoise`.
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    denoise: bool,
    /// Only this clip or recording (`astronaut`, `megamind`, `steady`, `wander`,
    /// `slow`, `cuts`, `call`); repeat for more. Default: all.
    #[arg(long)]
    only: Vec<String>,
}

fn main() -> Result<(), String> {
    let root = checkout();
    let args = Args::parse();
    let media = args.media.unwrap_or_else(|| root.join("target/real-media"));
    let out = args.out.unwrap_or_else(|| root.join("results/real"));
    let target = args
        .target
        .unwrap_or_else(|| root.join("models/targets/sunset.png"));
    let model = args
        .model
        .unwrap_or_else(gstlsydrelight::paths::default_model);
    let frames = args.frames;
    let setup = Setup {
        model: &model,
        target: &target,
        format: args.format,
        denoise: args.denoise,
    };
    init();
    print!("{}", report(&setup, &media, frames, &out, &args.only)?);
    println!(
        "before/after images and maps of the change (log luma ratio, grey for none) in {}",
        out.display()
    );
    Ok(())
}
