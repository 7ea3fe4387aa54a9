//! A long soak of the stateful engine: many frames of changing faces and lights,
//! checking every output for NaN/Inf and range, memory every block, and drift:
//! the same constant probe sequence, run every block, must settle to the same
//! output every time.
//!
//! ```text
//! cargo run --release --example soak -- [--frames 100000] [--model models/default] [--threads 2]
//! ```

use std::time::Instant;

use clap::Parser;
use deskstage::content::{Clip, Playlist};
use deskstage::dataset::Recording;
use gstlsydrelight::engine::{self, FramePolicy, Provider, Relighter, Skips, Source, Temporal};
use gstlsydrelight::frame::{FacePlace, Frame};
use gstlsydrelight::light::Light;
use gstlsydrelight::paths;
use lsydrelight_testkit::{default_model, person::network_input};

fn rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .map(str::to_string)
        })
        .and_then(|l| {
            l.split_whitespace()
                .nth(1)
                .and_then(|v| v.parse::<f64>().ok())
        })
        .map_or(0.0, |kb| kb / 1024.0)
}

/// A long soak of the stateful engine: NaN, range, memory and drift.
#[derive(Parser)]
struct Args {
    /// Frames to run.
    #[arg(long, default_value_t = 100_000)]
    frames: usize,
    /// The network's threads.
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// The model folder (default: the element's default model).
    #[arg(long)]
    model: Option<std::path::PathBuf>,
}

fn main() -> Result<(), String> {
    let args = Args::parse();
    let (frames, threads) = (args.frames, args.threads);
    let model = args.model.unwrap_or_else(default_model);

    let env = engine::environment(&paths::default_ort_library()).map_err(|e| e.to_string())?;
    let network = Relighter::new(env, &model, threads, Provider::Cpu).map_err(|e| e.to_string())?;
    let mut r = FramePolicy::new(network, Temporal::default(), Skips::default());
    r.set_target(&Light::uniform([0.9, 0.75, 0.6]))
        .map_err(|e| e.to_string())?;
    let res = r.relighter().resolution();

    // 60 distinct frames of a recorded call and their monitor lights, cycled.
    let rec = Recording::standard("cuts").ok_or("no cuts recording")?;
    let inputs: Vec<(Vec<f32>, Light)> = (0..60)
        .map(|i| {
            let f = rec.frame(i * 5, false);
            let monitor = Frame::packed_rgb(&f.monitor.data, f.monitor.width, f.monitor.height);
            (network_input(&f.face, res), Light::from_frame(&monitor))
        })
        .collect();
    let grey = Playlist::still(Clip::Solid(deskstage::math::Vec3::new(0.7, 0.7, 0.7))).frame(0.0);
    let probe_light = Light::from_frame(&Frame::packed_rgb(&grey.data, grey.width, grey.height));
    let probe = |r: &mut FramePolicy| -> Result<Vec<f32>, String> {
        let mut out = Vec::new();
        for _ in 0..60 {
            out = r
                .relight(
                    &inputs[0].0,
                    FacePlace::default(),
                    Source::Known(probe_light.clone()),
                    false,
                )
                .map_err(|e| e.to_string())?
                .relit
                .ok_or("NaN in the probe")?;
        }
        Ok(out)
    };

    let reference = probe(&mut r)?;
    let block = 10_000.min(frames);
    println!("| frames | seconds | ms/frame | RSS MiB | max drift | NaN/Inf | out of range |");
    println!("|---|---|---|---|---|---|---|");
    let started = Instant::now();
    let (mut done, mut bad, mut out_of_range) = (0usize, 0usize, 0usize);
    while done < frames {
        let t = Instant::now();
        for i in done..(done + block).min(frames) {
            let (img, light) = &inputs[(i * 7) % inputs.len()];
            // Every tenth frame of a stretch has no known source light.
            let source = if i % 10 == 3 {
                Source::Unknown
            } else {
                Source::Known(light.clone())
            };
            let out = r
                .relight(img, FacePlace::default(), source, i % 25 == 0)
                .map_err(|e| e.to_string())?;
            match out.relit {
                Some(v) => out_of_range += v.iter().filter(|x| !(0.0..=1.0).contains(*x)).count(),
                None => bad += 1,
            }
        }
        let n = (done + block).min(frames) - done;
        done += n;
        let drift = probe(&mut r)?
            .iter()
            .zip(&reference)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        println!(
            "| {done} | {:.0} | {:.2} | {:.1} | {drift:.2e} | {bad} | {out_of_range} |",
            started.elapsed().as_secs_f64(),
            1e3 * t.elapsed().as_secs_f64() / n as f64,
            rss_mb()
        );
    }
    if bad > 0 || out_of_range > 0 {
        return Err(format!(
            "{bad} frames had NaN/Inf and {out_of_range} values were out of range"
        ));
    }
    Ok(())
}
