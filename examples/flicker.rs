//! How much the element flickers, and where its error lies, on the standard
//! recordings against their exact ground truth (issue 16): per recording and
//! target the change error (the frame-to-frame change against the truth's
//! change) of the element and of the unrelit input, over the frame and over
//! the face region; the face region's RMSE; its error split into a smooth band
//! and a detail band (`recording::Bands`); and the detail band's energy against
//! the truth's (sharpness: below 1 the output is softer than the truth).
//!
//! With `--clean` the element also relights each recording's face filmed
//! without sensor noise (rendered once into `target/clean-faces/`): the detail
//! band of that run carries no noise, only what the transfer keeps of the
//! source light's shading (and the network's own error).
//!
//! With `--flow` it adds TecoGAN's tOF over the face region (as
//! `evaluate_element` gives it), of the element's output and of the input.
//!
//! ```text
//! cargo run --release --example flicker -- [--recordings steady,slow,cuts,call]
//!     [--frames 300] [--targets studio,sunset,left-key] [--clean] [--flow]
//!     [--set denoise=false] [--set reuse-interval=1]
//! ```

use clap::Parser;
use lsydrelight_testkit::{
    checkout,
    recording::{Score, clean_face_of, ensure_recording, property_setting, score_face},
};

/// Milliseconds a frame the element spent denoising and pasting the change
/// (its `paste-seconds` over the frames), under whatever else the machine ran.
fn paste_ms(s: &Score) -> f64 {
    s.stats["paste-seconds"].as_f64().unwrap_or(f64::NAN) * 1e3 / s.frames.max(1) as f64
}

/// The tOF cell: relit / input, or n/a without `--flow`.
fn tof(relit: Option<f64>, input: Option<f64>) -> String {
    match (relit, input) {
        (Some(r), Some(i)) => format!("{r:.4} / {i:.4}"),
        _ => "n/a".into(),
    }
}

/// How much the element flickers, and where its error lies, on the standard
/// recordings against their exact ground truth.
#[derive(Parser)]
struct Args {
    /// The simulator's recordings, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "steady,slow,cuts,call")]
    recordings: Vec<String>,
    /// Target presets, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "studio,sunset,left-key")]
    targets: Vec<String>,
    /// Frames of each recording.
    #[arg(long, default_value_t = 300)]
    frames: usize,
    /// The face filmed without sensor noise.
    #[arg(long)]
    clean: bool,
    /// Also TecoGAN's tOF (classical optical flow; slow).
    #[arg(long)]
    flow: bool,
    /// An element property, as property=value; repeatable, set in order.
    #[arg(long = "set", value_name = "PROPERTY=VALUE", value_parser = property_setting)]
    sets: Vec<(String, String)>,
}

fn main() -> Result<(), String> {
    let Args {
        recordings,
        targets,
        frames,
        clean,
        flow,
        sets,
    } = Args::parse();
    let props: Vec<(&str, &str)> = sets.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();

    println!(
        "| recording | target | face | change frame: relit / input | change region: relit / input | RMSE region: relit / input | smooth band: relit / input | detail band: relit / input | detail energy / truth's | paste ms/frame | tOF: relit / input |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    let mut totals: Vec<(String, Score)> = Vec::new();
    for name in &recordings {
        // The call is rendered at 90 frames for the other examples and tests.
        let frames = if name == "call" {
            frames.min(90)
        } else {
            frames
        };
        let dir = checkout().join(format!("target/recordings/{name}-{frames}"));
        ensure_recording(&dir, name, frames)?;
        let mut faces = vec![("noisy", dir.join("face.y4m"))];
        if clean {
            faces.push(("clean", clean_face_of(name, frames)?));
        }
        for target in &targets {
            for (kind, face) in &faces {
                let s = score_face(&dir, face, target, true, &props, flow)?;
                println!(
                    "| {name} | {target} | {kind} | {:.3} / {:.3} | {:.3} / {:.3} | {:.3} / {:.3} | {:.3} / {:.3} | {:.3} / {:.3} | {:.3} | {:.2} | {} |",
                    s.change_rmse,
                    s.input_change_rmse,
                    s.change_rmse_region,
                    s.input_change_rmse_region,
                    s.rmse_region,
                    s.input_rmse_region,
                    s.bands.smooth,
                    s.input_bands.smooth,
                    s.bands.detail,
                    s.input_bands.detail,
                    s.detail_energy_ratio,
                    paste_ms(&s),
                    tof(s.tof_region, s.input_tof_region),
                );
                totals.push((kind.to_string(), s));
            }
        }
    }
    for kind in ["noisy", "clean"] {
        let runs: Vec<&Score> = totals
            .iter()
            .filter(|(k, _)| k == kind)
            .map(|(_, s)| s)
            .collect();
        if runs.is_empty() {
            continue;
        }
        let mean =
            |f: &dyn Fn(&Score) -> f64| runs.iter().map(|s| f(s)).sum::<f64>() / runs.len() as f64;
        println!(
            "| mean | | {kind} | {:.3} / {:.3} | {:.3} / {:.3} | {:.3} / {:.3} | {:.3} / {:.3} | {:.3} / {:.3} | {:.3} | {:.2} | {} |",
            mean(&|s| s.change_rmse),
            mean(&|s| s.input_change_rmse),
            mean(&|s| s.change_rmse_region),
            mean(&|s| s.input_change_rmse_region),
            mean(&|s| s.rmse_region),
            mean(&|s| s.input_rmse_region),
            mean(&|s| s.bands.smooth),
            mean(&|s| s.input_bands.smooth),
            mean(&|s| s.bands.detail),
            mean(&|s| s.input_bands.detail),
            mean(&|s| s.detail_energy_ratio),
            mean(&paste_ms),
            tof(
                flow.then(|| mean(&|s| s.tof_region.unwrap_or(f64::NAN))),
                flow.then(|| mean(&|s| s.input_tof_region.unwrap_or(f64::NAN))),
            ),
        );
    }
    Ok(())
}
