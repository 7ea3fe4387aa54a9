//! `--quality`: what the output looks like without ground truth, the
//! scorecard's report with the element's defaults on real footage and the
//! recordings.

use lsydrelight_testkit::{
    checkout,
    footage::Format,
    init,
    scorecard::{Setup, report},
};

/// The scorecard's report with the element's defaults, fed RGB and I420, on
/// the first `frames` frames of each clip and recording.
pub(crate) fn quality(frames: usize) -> Result<String, String> {
    init();
    let root = checkout();
    let (model, target) = (
        gstlsydrelight::paths::default_model(),
        root.join("models/targets/sunset.png"),
    );
    let mut text = format!(
        "# What the output looks like, without ground truth\n\n\
         `cargo run --release --example benchmark -- --quality --frames {frames}`: the element's \
         defaults and default model, no monitor stream, relit to the sunset target (each \
         recording to its own); box edge and mottling in percent, pumping in levels, RMSE on \
         0-255 (`lsydrelight_testkit::scorecard`).\n"
    );
    for format in [Format::Rgb, Format::I420] {
        let setup = Setup {
            model: &model,
            target: &target,
            format,
            denoise: true,
        };
        text.push_str(&format!("\n## Fed {format:?}\n\n"));
        text.push_str(&report(
            &setup,
            &root.join("target/real-media"),
            frames,
            &root
                .join("results/tmp/quality")
                .join(format!("{format:?}").to_lowercase()),
            &[],
        )?);
    }
    Ok(text)
}
