//! The full run: each variant of the element (model, precision, threads,
//! temporal filters, skips) in a child process of its own, which runs the test
//! recordings through the element and scores them against their exact ground
//! truth, with its CPU seconds a frame, peak memory, and for some the latency
//! frame by frame.

use std::path::{Path, PathBuf};
use std::time::Instant;

use lsydrelight_testkit::recording::score_recording;
use serde::{Deserialize, Serialize};

use crate::latency::{LatencyResult, latency};
use crate::{cpu_seconds, recording_dir};

/// One configuration of the element.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct Variant {
    pub(crate) name: String,
    /// Which comparison it belongs to: model, precision, threads, temporal, skip.
    pub(crate) group: String,
    pub(crate) model: PathBuf,
    pub(crate) threads: u32,
    /// Further element properties, as gst-launch would set them.
    pub(crate) properties: Vec<(String, String)>,
    pub(crate) recordings: Vec<String>,
    /// Frame sizes to time frame by frame, in I420.
    pub(crate) latency_sizes: Vec<(u32, u32)>,
}

#[derive(Debug, Default, Serialize, Deserialize)]
struct RecordingResult {
    recording: String,
    frames: usize,
    rmse_region: f64,
    input_rmse_region: f64,
    change_rmse: f64,
    adjacent_rmse: f64,
    /// Share of adjacent frame pairs above each threshold, as in
    /// `lsydrelight_testkit::recording::Score::adjacent_over`.
    adjacent_over: Vec<f64>,
    fps: f64,
    stats: serde_json::Value,
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct VariantResult {
    variant: Variant,
    recordings: Vec<RecordingResult>,
    latency: Vec<LatencyResult>,
    cpu_seconds_per_frame: f64,
    peak_rss_mb: f64,
}

fn peak_rss_mb() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find(|l| l.starts_with("VmHWM:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|v| v.parse::<f64>().ok())
        .map_or(0.0, |kb| kb / 1024.0)
}

/// The variant's element properties as strings, with the model and threads.
pub(crate) fn properties(v: &Variant, threads: &str) -> Vec<(String, String)> {
    let mut props = vec![
        (
            "model-location".to_string(),
            v.model.to_string_lossy().into_owned(),
        ),
        ("threads".to_string(), threads.to_string()),
    ];
    props.extend(v.properties.iter().cloned());
    props
}

pub(crate) fn run_child(v: Variant) -> Result<VariantResult, String> {
    let cpu0 = cpu_seconds();
    let mut frames = 0;
    let mut recordings = Vec::new();
    for name in &v.recordings {
        let dir = recording_dir(name)?;
        let t = Instant::now();
        let props = properties(&v, &v.threads.to_string());
        let refs: Vec<(&str, &str)> = props
            .iter()
            .map(|(k, v)| (k.as_str(), v.as_str()))
            .collect();
        let s = score_recording(&dir, "sunset", true, &refs, false)?;
        frames += s.frames;
        recordings.push(RecordingResult {
            recording: name.clone(),
            frames: s.frames,
            rmse_region: s.rmse_region,
            input_rmse_region: s.input_rmse_region,
            change_rmse: s.change_rmse,
            adjacent_rmse: s.adjacent_rmse,
            adjacent_over: s.adjacent_over,
            fps: s.frames as f64 / t.elapsed().as_secs_f64(),
            stats: s.stats,
        });
    }
    let cpu = (cpu_seconds() - cpu0) / frames.max(1) as f64;
    let latency = v
        .latency_sizes
        .iter()
        .map(|&(w, h)| latency(&v, w, h, "I420", 150))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(VariantResult {
        cpu_seconds_per_frame: cpu,
        peak_rss_mb: peak_rss_mb(),
        recordings,
        latency,
        variant: v,
    })
}

pub(crate) fn variants(root: &Path, quick: bool) -> Vec<Variant> {
    let bench = root.join("target/bench-models");
    let default = root.join("models/default");
    let all = |quick_list: &[&str]| -> Vec<String> {
        if quick {
            quick_list.iter().map(|s| s.to_string()).collect()
        } else {
            ["steady", "slow", "cuts", "walkaway"]
                .iter()
                .map(|s| s.to_string())
                .collect()
        }
    };
    let base = |name: &str, group: &str, model: &Path| Variant {
        name: name.into(),
        group: group.into(),
        model: model.to_path_buf(),
        threads: 2,
        properties: vec![],
        recordings: all(&["cuts"]),
        latency_sizes: vec![],
    };
    let with = |mut v: Variant, props: &[(&str, &str)]| {
        v.properties = props
            .iter()
            .map(|(k, val)| (k.to_string(), val.to_string()))
            .collect();
        v
    };
    // Models are compared with every frame through the network.
    let mut v = vec![with(
        base("default", "model", &default),
        &[("reuse-interval", "1")],
    )];
    // Model size and resolution: every exported variant with the default element settings.
    for run in ["t-lcfn", "p-r96", "p-r160", "p-w0125", "e-r96"] {
        let m = bench.join(run);
        if m.join("model.json").exists() {
            v.push(with(base(run, "model", &m), &[("reuse-interval", "1")]));
        }
    }
    // Latency is timed with every frame running the network: the worst case.
    v.push(Variant {
        latency_sizes: vec![(1280, 720), (1920, 1080)],
        ..with(
            base("default, no skips", "model", &default),
            &[("reuse-interval", "1")],
        )
    });
    // The CUDA execution provider, where there is a GPU.
    if Path::new("/dev/nvidia0").exists() {
        v.push(Variant {
            latency_sizes: vec![(1280, 720), (1920, 1080)],
            ..with(
                base("default, cuda", "provider", &default),
                &[("reuse-interval", "1"), ("execution-provider", "cuda")],
            )
        });
    }
    // Precision: the fp16 variant the Python side exports, the shipped int8 one.
    for (p, m) in [
        ("fp16", bench.join("default-fp16")),
        ("int8", root.join("models/default-int8")),
    ] {
        if m.join("model.json").exists() {
            v.push(Variant {
                latency_sizes: vec![(1280, 720)],
                ..with(
                    base(&format!("default {p}"), "precision", &m),
                    &[("reuse-interval", "1")],
                )
            });
        }
    }
    // Threads.
    v.push(Variant {
        threads: 1,
        latency_sizes: vec![(1280, 720)],
        ..with(
            base("default, 1 thread", "threads", &default),
            &[("reuse-interval", "1")],
        )
    });
    // The paper's temporal filters.
    for (name, alpha, frames) in [
        ("no smoothing, no averaging", "1.0", "1"),
        ("averaging only", "1.0", "3"),
        ("smoothing only", "0.7", "1"),
    ] {
        v.push(with(
            base(name, "temporal", &default),
            &[
                ("alpha", alpha),
                ("average-frames", frames),
                ("reuse-interval", "1"),
            ],
        ));
    }
    // Each skip switched from its default, on every recording.
    let rec = all(&["steady", "walkaway"]);
    for (name, prop, value) in [
        ("no reuse", "reuse-interval", "1"),
        ("reuse every 2nd", "reuse-interval", "2"),
        ("reuse up to 6", "reuse-interval", "6"),
        ("no same-light skip", "skip-same-light", "false"),
        ("no absent skip", "skip-absent", "false"),
    ] {
        v.push(Variant {
            recordings: rec.clone(),
            ..with(base(name, "skip", &default), &[(prop, value)])
        });
    }
    v.push(Variant {
        recordings: rec.clone(),
        ..base("default skips", "skip", &default)
    });
    if quick {
        v.truncate(3);
    }
    v
}
