//! The element's side of the run-time against error benchmark.
//!
//! ```text
//! cargo run --release --example benchmark -- [--out results/benchmark] [--quick] [--group skip]
//! cargo run --release --example benchmark -- --stages [--rounds 3] [--only 1280x720/I420,...] [--threads 2] [--model models/default] [--out results/benchmark]
//! cargo run --release --example benchmark -- --first-frame [--repeats 7]
//! cargo run --release --example benchmark -- --reuse [--rounds 3] [--only steady,1280x720] [--out results/benchmark]
//! cargo run --release --example benchmark -- --quality [--frames 90] [--out results/benchmark]
//! cargo run --release --example benchmark -- --face-search [--rounds 3] [--out results/benchmark]
//! ```
//!
//! `--face-search` times the face detector at 1080p with and without its search
//! for small faces (`gstlsydrelight::face::search`) and writes `<out>/face-search.md`.
//!
//! `--reuse` measures what the reuse interval buys where the network dominates:
//! the element's own time a frame at 720p and 1080p (the recordings upscaled
//! upstream of it) on `steady`, `slow` and `cuts` with `reuse-interval` 1, 3 and 6,
//! in interleaved rounds, beside the face-region error of each interval at the
//! recordings' own size against exact ground truth; writes `<out>/reuse.md`.
//!
//! `--first-frame` times a live 720p pipeline from PLAYING to its first relit
//! buffer: model load, ONNX Runtime sessions, the face detector, the first
//! inference. The first start in a process also loads ONNX Runtime's library;
//! later ones (obs-gstreamer restarts its pipeline whenever the source is
//! hidden) do not.
//!
//! `--stages` times where the element's time goes, every frame through the network,
//! at 480p, 720p, 1080p and 2160p in I420, NV12 and BGRx, in interleaved rounds,
//! and writes `<out>/stages.md` (medians with min-max) beside published anchors.
//!
//! For each variant (model, precision, threads, temporal filters, skips) a child
//! process runs the test recordings through the real element and scores them
//! against their exact ground truth: error in the face region, the change error
//! (frame-to-frame change against the ground truth's change), throughput, CPU
//! seconds per frame and peak memory. Selected variants are also timed frame by
//! frame at 720p and 1080p for p50/p99 latency. Results go to
//! `<out>/element.json`; `python -m lsyd.evaluation.benchmark` adds the held-out accuracy,
//! the PyTorch peer and the hardware limit, and writes the tables and plot.
//!
//! `--quality` measures what the output looks like without ground truth (box
//! edges, mottling over the face, pumping) on real footage and on the
//! recordings (and `wander`), with the element's defaults fed RGB and I420,
//! and writes `<out>/quality.md` (`lsydrelight_testkit::scorecard`; before/after
//! images into `results/tmp/quality/`, not committed). `examples/real_footage.rs` prints the same
//! report for other settings.

mod face_search;
mod first_frame;
mod full_run;
mod latency;
mod quality;
mod reuse;
mod stages;

use std::path::PathBuf;
use std::process::Command;

use clap::{ArgGroup, Parser};
use lsydrelight_testkit::{checkout, recording::ensure_recording};

use face_search::face_search;
use first_frame::first_frame;
use full_run::{Variant, run_child, variants};
use quality::quality;
use reuse::reuse;
use stages::stages;

/// User plus system CPU seconds of this process.
pub(crate) fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name, which may contain spaces, are after the last ')'.
    let rest = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    // utime and stime are fields 14 and 15 of the whole line: 12 and 13 after the name.
    (ticks(11) + ticks(12)) / 100.0
}

pub(crate) fn recording_dir(name: &str) -> Result<PathBuf, String> {
    let data = checkout().join("data/recordings").join(name);
    if data.join("truth-sunset.y4m").exists() {
        return Ok(data);
    }
    let dir = checkout().join(format!("target/recordings/{name}-300"));
    ensure_recording(&dir, name, 300)?;
    Ok(dir)
}

/// The element's side of the run-time against error benchmark. With no mode,
/// the full run: every variant in its own process, into `<out>/element.json`.
#[derive(Parser)]
#[command(group(ArgGroup::new("mode").args(["stages", "first_frame", "reuse", "quality", "face_search"])))]
struct Args {
    /// Where results go (default: results/benchmark).
    #[arg(long)]
    out: Option<PathBuf>,
    /// The full run: fewer variants.
    #[arg(long)]
    quick: bool,
    /// The full run: only the variants of this group (e.g. skip).
    #[arg(long)]
    group: Option<String>,
    /// Where the element's time goes, stage by stage, at every size and format.
    #[arg(long)]
    stages: bool,
    /// Time from PLAYING to the first relit buffer of a live 720p pipeline.
    #[arg(long)]
    first_frame: bool,
    /// What the reuse interval buys, and what it costs in error.
    #[arg(long)]
    reuse: bool,
    /// What the output looks like, measured without ground truth.
    #[arg(long)]
    quality: bool,
    /// What looking for small faces costs the face detector at 1080p.
    #[arg(long)]
    face_search: bool,
    /// --stages, --reuse and --face-search: interleaved rounds.
    #[arg(long, default_value_t = 3)]
    rounds: usize,
    /// --stages: cases such as 1280x720/I420; --reuse: recordings and sizes such as steady,1280x720.
    #[arg(long, value_delimiter = ',')]
    only: Vec<String>,
    /// --stages: the network's threads.
    #[arg(long, default_value_t = 2)]
    threads: u32,
    /// --stages: the model folder (default: models/default).
    #[arg(long, requires = "stages")]
    model: Option<PathBuf>,
    /// --first-frame: pipeline starts (at least 2).
    #[arg(long, default_value_t = 7)]
    repeats: usize,
    /// --quality: frames of each clip.
    #[arg(long, default_value_t = 90)]
    frames: usize,
    /// One variant, as JSON, run in this process: how the full run starts its children.
    #[arg(long, hide = true)]
    child: Option<String>,
}

fn main() -> Result<(), String> {
    let args = Args::parse();
    if let Some(variant) = &args.child {
        let v: Variant = serde_json::from_str(variant).map_err(|e| e.to_string())?;
        let r = run_child(v)?;
        println!("{}", serde_json::to_string(&r).unwrap());
        return Ok(());
    }
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| checkout().join("results/benchmark"));
    std::fs::create_dir_all(&out).map_err(|e| e.to_string())?;
    if args.first_frame {
        let times = first_frame(args.repeats.max(2))?;
        let mut later = times[1..].to_vec();
        later.sort_by(f64::total_cmp);
        println!(
            "time to first relit frame, live 720p: {:.0} ms the first start in a process; \
             later starts median {:.0} ms ({:.0}-{:.0}, {} starts)",
            times[0],
            later[later.len() / 2],
            later[0],
            later[later.len() - 1],
            later.len()
        );
        return Ok(());
    }
    let table = if args.stages {
        let model = args
            .model
            .clone()
            .unwrap_or_else(|| checkout().join("models/default"));
        Some((
            "stages.md",
            stages(args.rounds, &args.only, args.threads, &model)?,
        ))
    } else if args.quality {
        Some(("quality.md", quality(args.frames)?))
    } else if args.reuse {
        Some(("reuse.md", reuse(args.rounds, &args.only)?))
    } else if args.face_search {
        Some(("face-search.md", face_search(args.rounds)?))
    } else {
        None
    };
    if let Some((name, table)) = table {
        let path = out.join(name);
        std::fs::write(&path, &table).map_err(|e| e.to_string())?;
        print!("{table}");
        eprintln!("wrote {}", path.display());
        return Ok(());
    }
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let group = args.group;
    let mut results = Vec::new();
    for v in variants(&checkout(), args.quick)
        .into_iter()
        .filter(|v| group.as_ref().is_none_or(|g| &v.group == g))
    {
        eprintln!("benchmark: {} ({})", v.name, v.group);
        // A process per variant: its own peak memory and a cold start.
        let output = Command::new(&exe)
            .arg("--child")
            .arg(serde_json::to_string(&v).unwrap())
            .output()
            .map_err(|e| e.to_string())?;
        let stdout = String::from_utf8_lossy(&output.stdout);
        match stdout
            .lines()
            .last()
            .map(serde_json::from_str::<serde_json::Value>)
        {
            Some(Ok(r)) if output.status.success() => results.push(r),
            _ => {
                return Err(format!(
                    "variant {} failed: {}",
                    v.name,
                    String::from_utf8_lossy(&output.stderr)
                ));
            }
        }
    }
    let path = out.join("element.json");
    std::fs::write(&path, serde_json::to_string_pretty(&results).unwrap())
        .map_err(|e| e.to_string())?;
    eprintln!("wrote {}", path.display());
    Ok(())
}
