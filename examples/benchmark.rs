//! The element's side of the run-time against error benchmark.
//!
//! ```text
//! cargo run --release --example benchmark -- [--out results/benchmark] [--quick] [--group skip]
//! cargo run --release --example benchmark -- --stages [--rounds 3] [--only 1280x720/I420,...] [--threads 2] [--model models/default] [--out results/benchmark]
//! cargo run --release --example benchmark -- --first-frame [--repeats 7]
//! cargo run --release --example benchmark -- --reuse [--rounds 3] [--only steady,1280x720] [--out results/benchmark]
//! cargo run --release --example benchmark -- --quality [--frames 90] [--out results/benchmark]
//! ```
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

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use clap::{ArgGroup, Parser};
use gst::prelude::*;
use lsydrelight_testkit::{
    checkout,
    footage::Format,
    init,
    recording::{ensure_recording, score_recording},
    scorecard::{Setup, report},
};
use serde::{Deserialize, Serialize};

/// One configuration of the element.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Variant {
    name: String,
    /// Which comparison it belongs to: model, precision, threads, temporal, skip.
    group: String,
    model: PathBuf,
    threads: u32,
    /// Further element properties, as gst-launch would set them.
    properties: Vec<(String, String)>,
    recordings: Vec<String>,
    /// Frame sizes to time frame by frame, in I420.
    latency_sizes: Vec<(u32, u32)>,
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

#[derive(Debug, Default, Serialize, Deserialize)]
struct LatencyResult {
    width: u32,
    height: u32,
    format: String,
    frames: usize,
    /// From a frame entering the element's face pad to it leaving `src`, one frame
    /// in flight at a time.
    p50_ms: f64,
    p99_ms: f64,
    fps: f64,
    /// Mean milliseconds a frame, from the element's statistics: in all, in ONNX
    /// Runtime, reading the face region (crop, conversion, resampling), putting the
    /// lighting change back, averaging and smoothing, and reading monitor frames.
    processing_ms: f64,
    network_ms: f64,
    crop_ms: f64,
    paste_ms: f64,
    smoothing_ms: f64,
    monitor_light_ms: f64,
    /// The rest, by stage (the element's `stats`): following the face, building
    /// the lighting change, the policy's deciding, the element's setup and finish,
    /// and the whole turn of a frame in the element up to handing it downstream.
    #[serde(default)]
    follow_ms: f64,
    #[serde(default)]
    change_ms: f64,
    #[serde(default)]
    decide_ms: f64,
    #[serde(default)]
    setup_ms: f64,
    #[serde(default)]
    finish_ms: f64,
    #[serde(default)]
    frame_ms: f64,
}

#[derive(Debug, Serialize, Deserialize)]
struct VariantResult {
    variant: Variant,
    recordings: Vec<RecordingResult>,
    latency: Vec<LatencyResult>,
    cpu_seconds_per_frame: f64,
    peak_rss_mb: f64,
}

/// User plus system CPU seconds of this process.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name, which may contain spaces, are after the last ')'.
    let rest = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    // utime and stime are fields 14 and 15 of the whole line: 12 and 13 after the name.
    (ticks(11) + ticks(12)) / 100.0
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

fn recording_dir(name: &str) -> Result<PathBuf, String> {
    let data = checkout().join("data/recordings").join(name);
    if data.join("truth-sunset.y4m").exists() {
        return Ok(data);
    }
    let dir = checkout().join(format!("target/recordings/{name}-300"));
    ensure_recording(&dir, name, 300)?;
    Ok(dir)
}

/// The variant's element properties as strings, with the model and threads.
fn properties(v: &Variant, threads: &str) -> Vec<(String, String)> {
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

/// Per-frame latency through the element at a frame size. Frames go in one at a time
/// (the next after the last came out), so each one's time is its own, not time spent
/// queued behind the one before; pad probes time each frame in and out.
/// An appsrc of 30 fps RGB frames in time format.
fn rgb_source(width: i32, height: i32) -> gst_app::AppSrc {
    gst_app::AppSrc::builder()
        .caps(
            &gst_video::VideoCapsBuilder::new()
                .format(gst_video::VideoFormat::Rgb)
                .width(width)
                .height(height)
                .framerate(gst::Fraction::new(30, 1))
                .build(),
        )
        .format(gst::Format::Time)
        .build()
}

/// Records when each buffer with a timestamp passes `pad`, then calls `after_each`.
fn log_buffer_times(
    pad: &gst::Pad,
    log: Arc<Mutex<Vec<(u64, Instant)>>>,
    after_each: impl Fn() + Send + Sync + 'static,
) {
    pad.add_probe(gst::PadProbeType::BUFFER, move |_, info| {
        if let Some(pts) = info.buffer().and_then(|b| b.pts()) {
            log.lock().unwrap().push((pts.nseconds(), Instant::now()));
            after_each();
        }
        gst::PadProbeReturn::Ok
    });
}

fn latency(
    v: &Variant,
    w: u32,
    h: u32,
    format: &str,
    frames: usize,
) -> Result<LatencyResult, String> {
    init();
    let recording = deskstage::dataset::Recording::standard("call").ok_or("no call recording")?;
    // Rendered beforehand, so the renderer does not compete with the element.
    let shown: Vec<_> = (0..30).map(|i| recording.frame(i, false)).collect();
    let pipeline = gst::Pipeline::new();
    let src = rgb_source(480, 360);
    let scale = gst::parse::bin_from_description(
        &format!(
            "videoscale ! videoconvert ! capsfilter caps=video/x-raw,format={format},width={w},height={h}"
        ),
        true,
    )
    .map_err(|e| e.to_string())?;
    let mon = rgb_source(256, 144);
    let r = gst::ElementFactory::make("lsydrelight")
        .name("r")
        .build()
        .map_err(|e| e.to_string())?;
    for (k, val) in properties(v, &v.threads.to_string()) {
        r.set_property_from_str(&k, &val);
    }
    let sink = gst::ElementFactory::make("fakesink")
        .property("sync", false)
        .build()
        .map_err(|e| e.to_string())?;
    pipeline
        .add_many([
            src.upcast_ref(),
            scale.upcast_ref(),
            mon.upcast_ref(),
            &r,
            &sink,
        ])
        .map_err(|e| e.to_string())?;
    gst::Element::link_many([src.upcast_ref(), scale.upcast_ref(), &r, &sink])
        .map_err(|e| e.to_string())?;
    mon.link_pads(None, &r, Some("monitor_sink"))
        .map_err(|e| e.to_string())?;

    let entered: Arc<Mutex<Vec<(u64, Instant)>>> = Arc::default();
    let left: Arc<Mutex<Vec<(u64, Instant)>>> = Arc::default();
    let (done_tx, done_rx) = std::sync::mpsc::channel::<()>();
    let done_tx = Mutex::new(done_tx);
    log_buffer_times(&r.static_pad("sink").unwrap(), entered.clone(), || {});
    log_buffer_times(&r.static_pad("src").unwrap(), left.clone(), move || {
        let _ = done_tx.lock().unwrap().send(());
    });
    pipeline
        .set_state(gst::State::Playing)
        .map_err(|e| e.to_string())?;
    let started = Instant::now();
    let feeder = std::thread::spawn(move || {
        let frame = gst::ClockTime::from_nseconds(1_000_000_000 / 30);
        let push = |app: &gst_app::AppSrc, img: &deskstage::monitor::RgbImage, i: usize| {
            let mut b = gst::Buffer::from_slice(img.data.clone());
            {
                let b = b.get_mut().unwrap();
                b.set_pts(frame * i as u64);
                b.set_duration(frame);
            }
            app.push_buffer(b).is_ok()
        };
        // The monitor runs a frame ahead: the element knows which monitor frame lit
        // face frame i once it has seen the one after it.
        let mut ok = push(&mon, &shown[0].monitor, 0);
        for i in 0..frames {
            ok = ok
                && if i + 1 < frames {
                    push(&mon, &shown[(i + 1) % 30].monitor, i + 1)
                } else {
                    mon.end_of_stream().is_ok()
                };
            ok = ok && push(&src, &shown[i % 30].face, i);
            if !ok
                || done_rx
                    .recv_timeout(std::time::Duration::from_secs(60))
                    .is_err()
            {
                break;
            }
        }
        let _ = src.end_of_stream();
        let _ = mon.end_of_stream();
    });
    let bus = pipeline.bus().unwrap();
    let msg = bus.timed_pop_filtered(
        gst::ClockTime::from_seconds(600),
        &[gst::MessageType::Eos, gst::MessageType::Error],
    );
    let elapsed = started.elapsed();
    feeder.join().map_err(|_| "feeder panicked")?;
    let stats = r.property::<gst::Structure>("stats");
    pipeline
        .set_state(gst::State::Null)
        .map_err(|e| e.to_string())?;
    if let Some(m) = msg
        && let gst::MessageView::Error(e) = m.view()
    {
        return Err(e.error().to_string());
    }
    let entered = entered.lock().unwrap();
    let left = left.lock().unwrap();
    let mut lat: Vec<f64> = left
        .iter()
        .filter_map(|(pts, out)| {
            entered
                .iter()
                .find(|(p, _)| p == pts)
                .map(|(_, inn)| out.duration_since(*inn).as_secs_f64() * 1e3)
        })
        .collect();
    // The first frames load and warm up ONNX Runtime.
    let warm = lat.len().min(10);
    lat.drain(..warm);
    lat.sort_by(|a, b| a.total_cmp(b));
    let pct = |p: f64| {
        lat.get(((lat.len() as f64 - 1.0) * p).round() as usize)
            .copied()
            .unwrap_or(f64::NAN)
    };
    let frames_out = left.len();
    let per_frame_ms =
        |field: &str| stats.get::<f64>(field).unwrap_or(f64::NAN) * 1e3 / frames_out.max(1) as f64;
    Ok(LatencyResult {
        width: w,
        height: h,
        format: format.to_string(),
        frames: frames_out,
        p50_ms: pct(0.5),
        p99_ms: pct(0.99),
        fps: frames_out as f64 / elapsed.as_secs_f64(),
        processing_ms: per_frame_ms("processing-seconds"),
        network_ms: per_frame_ms("network-seconds"),
        crop_ms: per_frame_ms("crop-seconds"),
        paste_ms: per_frame_ms("paste-seconds"),
        smoothing_ms: per_frame_ms("smoothing-seconds"),
        monitor_light_ms: per_frame_ms("monitor-light-seconds"),
        follow_ms: per_frame_ms("face-seconds"),
        change_ms: per_frame_ms("change-seconds"),
        decide_ms: per_frame_ms("decide-seconds"),
        setup_ms: per_frame_ms("setup-seconds"),
        finish_ms: per_frame_ms("finish-seconds"),
        frame_ms: per_frame_ms("frame-seconds"),
    })
}

fn run_child(v: Variant) -> Result<VariantResult, String> {
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

fn variants(root: &Path, quick: bool) -> Vec<Variant> {
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

/// Published per-frame figures of NVIDIA Maxine's video relighting at 720p on
/// data-centre GPUs (from the project's issue 11): anchors, not measured here.
const MAXINE_720P_MS: [(&str, f64); 3] = [("T4", 54.0), ("A40", 17.1), ("L40", 8.0)];

/// Where the time goes at each size and format, every frame through the network,
/// in `rounds` interleaved rounds; a markdown table of medians and min-max.
fn stages(rounds: usize, only: &[String], threads: u32, model: &Path) -> Result<String, String> {
    let every_frame = Variant {
        name: "every frame".into(),
        group: "stages".into(),
        model: model.to_path_buf(),
        threads,
        properties: vec![("reuse-interval".into(), "1".into())],
        recordings: vec![],
        latency_sizes: vec![],
    };
    let cases: Vec<((u32, u32), &str)> = [(854, 480), (1280, 720), (1920, 1080), (3840, 2160)]
        .into_iter()
        .flat_map(|size| ["I420", "NV12", "BGRx"].map(|format| (size, format)))
        .filter(|&((w, h), format)| {
            only.is_empty() || only.iter().any(|o| *o == format!("{w}x{h}/{format}"))
        })
        .collect();
    let mut runs: Vec<Vec<LatencyResult>> = cases.iter().map(|_| Vec::new()).collect();
    for round in 0..rounds {
        for (&((w, h), format), results) in cases.iter().zip(&mut runs) {
            eprintln!("stages: round {} {w}x{h} {format}", round + 1);
            results.push(latency(&every_frame, w, h, format, 60)?);
        }
    }
    let spread = |xs: Vec<f64>| {
        let mut xs = xs;
        xs.sort_by(f64::total_cmp);
        let median = xs[xs.len() / 2];
        format!("{median:.2} ({:.2}-{:.2})", xs[0], xs[xs.len() - 1])
    };
    let anchors: Vec<String> = MAXINE_720P_MS
        .iter()
        .map(|(gpu, ms)| format!("{ms} ms on {gpu}"))
        .collect();
    let mut out = vec![
        format!(
            "Per frame, every frame through the network (`{}`), one frame in flight, network on \
             {threads} thread(s); median (min-max) of {rounds} interleaved rounds of 60 frames (10 more to warm up) \
             on this 2-core CPU. Published anchor, not measured here: NVIDIA Maxine video \
             relighting at 720p, {}.",
            model.strip_prefix(checkout()).unwrap_or(model).display(),
            anchors.join(", ")
        ),
        String::new(),
        "| input | format | p50 ms | p99 ms | element ms | network | crop | paste | rest | fps |"
            .into(),
        "|---|---|---|---|---|---|---|---|---|---|".into(),
    ];
    let mut rest = vec![
        String::new(),
        "The rest, by stage (same runs, ms a frame): following the face (tracker, and \
         the detector every 5th frame), building the lighting change, the temporal \
         smoothing, the policy's deciding, the element's setup (lock, target, mapping \
         the frame) and finish; outside: the frame's time in the element beyond these \
         (its monitor frame's light, `monitor_src`, QoS)."
            .into(),
        String::new(),
        "| input | format | rest | follow | change | smoothing | decide | setup | finish | outside |"
            .into(),
        "|---|---|---|---|---|---|---|---|---|---|".into(),
    ];
    for (((w, h), format), results) in cases.iter().zip(&runs) {
        let col = |f: &dyn Fn(&LatencyResult) -> f64| spread(results.iter().map(f).collect());
        out.push(format!(
            "| {w}x{h} | {format} | {} | {} | {} | {} | {} | {} | {} | {} |",
            col(&|x| x.p50_ms),
            col(&|x| x.p99_ms),
            col(&|x| x.processing_ms),
            col(&|x| x.network_ms),
            col(&|x| x.crop_ms),
            col(&|x| x.paste_ms),
            col(&|x| x.processing_ms - x.network_ms - x.crop_ms - x.paste_ms),
            col(&|x| x.fps),
        ));
        rest.push(format!(
            "| {w}x{h} | {format} | {} | {} | {} | {} | {} | {} | {} | {} |",
            col(&|x| x.processing_ms - x.network_ms - x.crop_ms - x.paste_ms),
            col(&|x| x.follow_ms),
            col(&|x| x.change_ms),
            col(&|x| x.smoothing_ms),
            col(&|x| x.decide_ms),
            col(&|x| x.setup_ms),
            col(&|x| x.finish_ms),
            col(&|x| x.frame_ms - x.processing_ms),
        ));
    }
    out.extend(rest);
    Ok(out.join("\n") + "\n")
}

/// Recordings and intervals of `--reuse`.
const REUSE_RECORDINGS: [&str; 3] = ["steady", "slow", "cuts"];
const REUSE_INTERVALS: [u32; 3] = [1, 3, 6];

/// A video's frames decoded into memory, with their caps: what `--reuse` feeds the
/// element, so nothing upstream competes with it for the cores while it is timed.
struct Decoded {
    caps: gst::Caps,
    frames: Vec<gst::Buffer>,
}

/// `<dir>/<file>` decoded, scaled to `size` in I420 when given.
fn decode(dir: &Path, file: &str, size: Option<(u32, u32)>) -> Result<Decoded, String> {
    init();
    let scale = size.map_or(String::new(), |(w, h)| {
        format!("! videoscale ! videoconvert ! video/x-raw,format=I420,width={w},height={h}")
    });
    let pipeline = gst::parse::launch(&format!(
        "{} {scale} ! appsink name=frames sync=false",
        lsydrelight_testkit::recording::play_y4m(&dir.join(file))
    ))
    .map_err(|e| e.to_string())?
    .downcast::<gst::Pipeline>()
    .map_err(|_| "not a pipeline")?;
    let sink = pipeline
        .by_name("frames")
        .and_then(|s| s.downcast::<gst_app::AppSink>().ok())
        .ok_or("no appsink")?;
    pipeline
        .set_state(gst::State::Playing)
        .map_err(|e| e.to_string())?;
    let (mut caps, mut frames) = (None, Vec::new());
    while let Ok(sample) = sink.pull_sample() {
        caps = caps.or(sample.caps_owned());
        frames.extend(sample.buffer_owned());
    }
    pipeline
        .set_state(gst::State::Null)
        .map_err(|e| e.to_string())?;
    Ok(Decoded {
        caps: caps.ok_or_else(|| format!("{file}: no frames"))?,
        frames,
    })
}

/// Frames that warm the element up before `--reuse` counts CPU time: loading the
/// model, ONNX Runtime's first runs.
const WARM_FRAMES: u64 = 10;

/// The element's time on decoded frames (a face stream and its monitor stream),
/// pushed as fast as it takes them: CPU milliseconds a frame of the whole process
/// after the first [`WARM_FRAMES`] (every thread: the element, ONNX Runtime's, and
/// the copy of each frame that gives the element a writable buffer, as a camera
/// does), wall milliseconds a frame of its own turn (`frame-seconds`), and its `stats`.
fn element_time(
    face: &Decoded,
    monitor: &Decoded,
    target: &Path,
    interval: u32,
) -> Result<(f64, f64, gst::Structure), String> {
    let pipeline = gst::Pipeline::new();
    let source = |d: &Decoded| {
        gst_app::AppSrc::builder()
            .caps(&d.caps)
            .format(gst::Format::Time)
            .block(true)
            .max_buffers(4)
            .build()
    };
    let (face_src, monitor_src) = (source(face), source(monitor));
    let r = gst::ElementFactory::make("lsydrelight")
        .build()
        .map_err(|e| e.to_string())?;
    r.set_property("target-location", target.to_str().unwrap());
    // The recordings' person, relit with their own model, as the error runs are.
    r.set_property(
        "model-location",
        lsydrelight_testkit::default_model().to_str().unwrap(),
    );
    r.set_property("reuse-interval", interval);
    let sink = gst::ElementFactory::make("fakesink")
        .property("sync", false)
        .build()
        .map_err(|e| e.to_string())?;
    pipeline
        .add_many([face_src.upcast_ref(), monitor_src.upcast_ref(), &r, &sink])
        .map_err(|e| e.to_string())?;
    let warm: Arc<Mutex<(u64, f64)>> = Arc::default();
    let count = warm.clone();
    r.static_pad("src")
        .unwrap()
        .add_probe(gst::PadProbeType::BUFFER, move |_, _| {
            let mut c = count.lock().unwrap();
            c.0 += 1;
            if c.0 == WARM_FRAMES {
                c.1 = cpu_seconds();
            }
            gst::PadProbeReturn::Ok
        });
    gst::Element::link_many([face_src.upcast_ref(), &r, &sink]).map_err(|e| e.to_string())?;
    monitor_src
        .link_pads(None, &r, Some("monitor_sink"))
        .map_err(|e| e.to_string())?;
    pipeline
        .set_state(gst::State::Playing)
        .map_err(|e| e.to_string())?;
    std::thread::scope(|scope| {
        for (src, d) in [(&face_src, face), (&monitor_src, monitor)] {
            scope.spawn(move || {
                for b in &d.frames {
                    if src.push_buffer(b.copy()).is_err() {
                        break;
                    }
                }
                let _ = src.end_of_stream();
            });
        }
    });
    let msg = pipeline.bus().unwrap().timed_pop_filtered(
        gst::ClockTime::from_seconds(600),
        &[gst::MessageType::Eos, gst::MessageType::Error],
    );
    let cpu = cpu_seconds();
    let stats = r.property::<gst::Structure>("stats");
    pipeline
        .set_state(gst::State::Null)
        .map_err(|e| e.to_string())?;
    match msg.as_ref().map(|m| m.view()) {
        Some(gst::MessageView::Eos(_)) => {}
        Some(gst::MessageView::Error(e)) => return Err(e.error().to_string()),
        _ => return Err("the recording did not finish in 10 minutes".into()),
    }
    let (out, cpu_warm) = *warm.lock().unwrap();
    let cpu_ms = (cpu - cpu_warm) * 1e3 / out.saturating_sub(WARM_FRAMES).max(1) as f64;
    let frames = stats.get::<u64>("frames").unwrap_or(0).max(1) as f64;
    let seconds = stats.get::<f64>("frame-seconds").unwrap_or(f64::NAN);
    Ok((cpu_ms, seconds * 1e3 / frames, stats))
}

/// What the reuse interval buys: a markdown table of the element's time a frame
/// at 720p and 1080p (median and min-max of `rounds` rounds, the intervals
/// interleaved within each) and the speed-up against every frame through the
/// network, beside the error at the recordings' own size.
fn reuse(rounds: usize, only: &[String]) -> Result<String, String> {
    let wanted = |what: String| only.is_empty() || only.iter().any(|o| what.contains(o.as_str()));
    let sizes: Vec<(u32, u32)> = [(1280u32, 720u32), (1920, 1080)]
        .into_iter()
        .filter(|(w, h)| wanted(format!("{w}x{h}")))
        .collect();
    let names: Vec<&str> = REUSE_RECORDINGS
        .into_iter()
        .filter(|name| wanted(name.to_string()))
        .collect();
    let dirs: Vec<PathBuf> = names
        .iter()
        .map(|name| recording_dir(name))
        .collect::<Result<_, _>>()?;
    let mut error = Vec::new();
    for (name, dir) in names.iter().zip(&dirs) {
        for interval in REUSE_INTERVALS {
            eprintln!("reuse: error {name}, interval {interval}");
            let interval = interval.to_string();
            let props = [("reuse-interval", interval.as_str())];
            error.push(score_recording(dir, "sunset", true, &props, false)?);
        }
    }
    let median = |xs: &[f64]| {
        let mut xs = xs.to_vec();
        xs.sort_by(f64::total_cmp);
        xs.get(xs.len() / 2).copied().unwrap_or(f64::NAN)
    };
    let spread = |xs: &[f64]| {
        let lo = xs.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        format!("{:.2} ({lo:.2}-{hi:.2})", median(xs))
    };
    let mut rows = Vec::new();
    for &(w, h) in &sizes {
        for (d, dir) in dirs.iter().enumerate() {
            let name = names[d];
            eprintln!("reuse: decoding {name} at {w}x{h}");
            let face = decode(dir, "face.y4m", Some((w, h)))?;
            let monitor = decode(dir, "monitor.y4m", None)?;
            let target = dir.join("target-sunset.png");
            let mut times = vec![(Vec::new(), Vec::new(), 0u64, 0u64); REUSE_INTERVALS.len()];
            for round in 0..rounds {
                for (k, &interval) in REUSE_INTERVALS.iter().enumerate() {
                    eprintln!(
                        "reuse: round {} {name} {w}x{h} interval {interval}",
                        round + 1
                    );
                    let (cpu, ms, stats) = element_time(&face, &monitor, &target, interval)?;
                    let stat = |f: &str| stats.get::<u64>(f).unwrap_or(0);
                    times[k].0.push(cpu);
                    times[k].1.push(ms);
                    times[k].2 = stat("frames");
                    times[k].3 = stat("relit");
                }
            }
            for (k, &interval) in REUSE_INTERVALS.iter().enumerate() {
                let (cpu, ms, frames, relit) = &times[k];
                let e = &error[d * REUSE_INTERVALS.len() + k];
                rows.push(format!(
                    "| {name} | {interval} | {w}x{h} | {} | {:.2}x | {} | {:.2}x | {relit}/{frames} | {:.3} | {:.3} |",
                    spread(cpu),
                    median(&times[0].0) / median(cpu),
                    spread(ms),
                    median(&times[0].1) / median(ms),
                    e.rmse_region,
                    e.change_rmse,
                ));
            }
        }
    }
    let mut out = vec![
        format!(
            "appsrc ! lsydrelight ! fakesink, the recordings decoded and upscaled to I420 \
             beforehand, 2 threads. CPU ms a frame: the process's CPU time (every thread, and \
             a copy of each frame as a camera's fresh buffer) after {WARM_FRAMES} frames, a \
             measure that holds on a shared machine; wall ms: the element's own turn a frame \
             (`stats` frame-seconds), which another job's load stretches. Median (min-max) of \
             {rounds} rounds, the intervals interleaved; speed-ups against every frame through \
             the network (interval 1) on the same recording and size. Face-region RMSE and \
             change RMSE on 0-255 at the recordings' own 480 x 360 against exact ground truth \
             (sunset target), one run."
        ),
        String::new(),
        "| recording | interval | size | CPU ms a frame | speed-up | wall ms | speed-up | network runs | RMSE face region | change RMSE |"
            .into(),
        "|---|---|---|---|---|---|---|---|---|---|".into(),
    ];
    out.extend(rows);
    Ok(out.join("\n") + "\n")
}

/// Milliseconds from PLAYING to the first relit buffer of a fresh live pipeline,
/// `repeats` times in this process.
fn first_frame(repeats: usize) -> Result<Vec<f64>, String> {
    init();
    let mut times = Vec::new();
    for _ in 0..repeats {
        let pipeline = gst::parse::launch(
            "videotestsrc is-live=true ! video/x-raw,width=1280,height=720,framerate=30/1 \
             ! lsydrelight name=r ! fakesink sync=false",
        )
        .map_err(|e| e.to_string())?
        .downcast::<gst::Bin>()
        .expect("a pipeline is a bin");
        let (tx, rx) = std::sync::mpsc::channel();
        let tx = Mutex::new(Some(tx));
        let relit = pipeline.by_name("r").expect("the element");
        relit
            .static_pad("src")
            .expect("src")
            .add_probe(gst::PadProbeType::BUFFER, move |_, _| {
                if let Some(tx) = tx.lock().unwrap().take() {
                    let _ = tx.send(Instant::now());
                }
                gst::PadProbeReturn::Ok
            });
        let started = Instant::now();
        pipeline
            .set_state(gst::State::Playing)
            .map_err(|e| e.to_string())?;
        let first = rx
            .recv_timeout(std::time::Duration::from_secs(30))
            .map_err(|_| "no relit frame within 30 s")?;
        times.push(first.duration_since(started).as_secs_f64() * 1e3);
        pipeline
            .set_state(gst::State::Null)
            .map_err(|e| e.to_string())?;
    }
    Ok(times)
}

/// The scorecard's report with the element's defaults, fed RGB and I420, on
/// the first `frames` frames of each clip and recording.
fn quality(frames: usize) -> Result<String, String> {
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
        )?);
    }
    Ok(text)
}

/// The element's side of the run-time against error benchmark. With no mode,
/// the full run: every variant in its own process, into `<out>/element.json`.
#[derive(Parser)]
#[command(group(ArgGroup::new("mode").args(["stages", "first_frame", "reuse", "quality"])))]
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
    /// --stages and --reuse: interleaved rounds.
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
