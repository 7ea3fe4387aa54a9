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
//!     [--denoise true|false]
//! ```
//!
//! The element runs with its defaults (`denoise` on unless `--denoise false`),
//! fed packed RGB or, as webcams deliver frames, I420. The model is the
//! element's default, the starter model for anyone, unless `--model` names
//! another. The real clips are fetched by `scripts/setup.sh full` into
//! `target/real-media`.

use std::path::PathBuf;

use lsydrelight_testkit::{
    checkout,
    flags::flag,
    footage::Format,
    init,
    scorecard::{Setup, report},
};

fn main() -> Result<(), String> {
    let root = checkout();
    let media = flag("--media").map_or_else(|| root.join("target/real-media"), PathBuf::from);
    let out = flag("--out").map_or_else(|| root.join("results/real"), PathBuf::from);
    let target =
        flag("--target").map_or_else(|| root.join("models/targets/sunset.png"), PathBuf::from);
    let model = flag("--model").map_or_else(gstlsydrelight::paths::default_model, PathBuf::from);
    let frames: usize =
        flag("--frames").map_or(Ok(90), |v| v.parse().map_err(|_| "bad --frames"))?;
    let format = flag("--format").map_or(Ok(Format::Rgb), |f| Format::parse(&f))?;
    let setup = Setup {
        model: &model,
        target: &target,
        format,
        denoise: match flag("--denoise").as_deref() {
            None | Some("true") => true,
            Some("false") => false,
            Some(other) => return Err(format!("--denoise {other}: true or false")),
        },
    };
    init();
    print!("{}", report(&setup, &media, frames, &out)?);
    println!(
        "before/after images and maps of the change (log luma ratio, grey for none) in {}",
        out.display()
    );
    Ok(())
}
