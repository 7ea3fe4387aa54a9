//! Scores the element end to end on a simulator recording against its exact
//! ground truth, for every target light, and records the figures in a model's
//! manifest (`metrics.element`), which the end-to-end test checks against.
//! Beside the change error it gives TecoGAN's tOF (classical optical flow, no
//! network weights) for the relit output and for the unrelit input; ms/frame
//! leaves out the time computing the flow.
//!
//! ```text
//! cargo run --release --example evaluate_element -- [--recording call] [--frames 90]
//!     [--model models/default] [--record]
//!     [--predicted] [--clean-face] [--set alpha=1 --set prediction-weight=1 ...]
//! ```
//!
//! `--predicted` leaves the monitor stream out, so the element predicts the
//! source light from the face (its default use); `--clean-face` feeds the
//! recording's face without the camera's noise (rendered once into
//! `target/clean-faces/`, as `examples/flicker.rs` renders it); `--set` gives the element
//! other property values. Each makes figures that are not the model card's,
//! so none goes with `--record`.

use clap::Parser;
use lsydrelight_testkit::{
    checkout, default_model,
    recording::{clean_face_of, ensure_recording, property_setting, score_face},
};
use std::path::PathBuf;

/// Scores the element end to end on a simulator recording, every target light.
#[derive(Parser)]
struct Args {
    /// The simulator's recording (`deskstage` names: call, steady, slow, cuts, ...).
    #[arg(long, default_value = "call")]
    recording: String,
    /// Frames of it.
    #[arg(long, default_value_t = 90)]
    frames: usize,
    /// The model folder (default: the element's default model).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Write the figures into the model's manifest (`metrics.element`).
    #[arg(long)]
    record: bool,
    /// Leave the monitor stream out: the element predicts the source light.
    #[arg(long)]
    predicted: bool,
    /// Feed the recording's face without the camera's noise.
    #[arg(long)]
    clean_face: bool,
    /// An element property, NAME=VALUE as gst-launch takes it; repeat for more.
    #[arg(long = "set", value_parser = property_setting)]
    properties: Vec<(String, String)>,
}

fn main() -> Result<(), String> {
    let Args {
        recording,
        frames,
        model,
        record,
        predicted,
        clean_face,
        properties,
    } = Args::parse();
    if record && (predicted || clean_face || !properties.is_empty()) {
        return Err(
            "--record keeps the model card's figures, made with the monitor stream, the \
                    camera's noise and the element's defaults: leave out --predicted, \
                    --clean-face and --set to record"
                .into(),
        );
    }
    let model = model.unwrap_or_else(default_model);

    let dir = checkout().join(format!("target/recordings/{recording}-{frames}"));
    ensure_recording(&dir, &recording, frames)?;
    let face = if clean_face {
        clean_face_of(&recording, frames)?
    } else {
        dir.join("face.y4m")
    };
    let mut results = serde_json::Map::new();
    let set: Vec<String> = properties.iter().map(|(k, v)| format!("{k}={v}")).collect();
    println!(
        "{recording}, model {}: source light {}, face {}, properties {}\n",
        model.display(),
        if predicted {
            "predicted"
        } else {
            "from the monitor stream"
        },
        if clean_face {
            "without the camera's noise"
        } else {
            "as filmed"
        },
        if set.is_empty() {
            "the defaults".to_string()
        } else {
            set.join(" ")
        },
    );
    println!(
        "| target | frames | RMSE face region | RMSE frame | input RMSE region | change RMSE | tOF face region | input tOF | ms/frame |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let model_location = model.to_str().ok_or("model path is not UTF-8")?;
    let props: Vec<(&str, &str)> = std::iter::once(("model-location", model_location))
        .chain(properties.iter().map(|(k, v)| (k.as_str(), v.as_str())))
        .collect();
    for target in ["studio", "sunset", "left-key"] {
        let s = score_face(&dir, &face, target, !predicted, &props, true)?;
        println!(
            "| {target} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.4} | {:.4} | {:.1} |",
            s.frames,
            s.rmse_region,
            s.rmse_frame,
            s.input_rmse_region,
            s.change_rmse,
            s.tof_region.unwrap_or(f64::NAN),
            s.input_tof_region.unwrap_or(f64::NAN),
            s.ms_per_frame
        );
        results.insert(target.into(), serde_json::to_value(&s).unwrap());
    }
    let key = format!("{recording}_{frames}");
    if record {
        let path = model.join("model.json");
        let mut m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).map_err(|e| e.to_string())?)
                .map_err(|e| e.to_string())?;
        m["metrics"]["element"][&key] = serde_json::json!({
            "command": format!("cargo run --release --example evaluate_element -- --recording {recording} --frames {frames} --record"),
            "targets": results,
        });
        std::fs::write(&path, serde_json::to_string_pretty(&m).unwrap() + "\n")
            .map_err(|e| e.to_string())?;
        println!("recorded in {}", path.display());
    }
    Ok(())
}
