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
//! ```

use clap::Parser;
use lsydrelight_testkit::{
    checkout, default_model,
    recording::{ensure_recording, score_recording},
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
}

fn main() -> Result<(), String> {
    let Args {
        recording,
        frames,
        model,
        record,
    } = Args::parse();
    let model = model.unwrap_or_else(default_model);

    let dir = checkout().join(format!("target/recordings/{recording}-{frames}"));
    ensure_recording(&dir, &recording, frames)?;
    let mut results = serde_json::Map::new();
    println!(
        "| target | frames | RMSE face region | RMSE frame | input RMSE region | change RMSE | tOF face region | input tOF | ms/frame |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for target in ["studio", "sunset", "left-key"] {
        let props = [(
            "model-location",
            model.to_str().ok_or("model path is not UTF-8")?,
        )];
        let s = score_recording(&dir, target, true, &props, true)?;
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
