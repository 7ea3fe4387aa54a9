//! `--reuse`: what the reuse interval buys where the network dominates, the
//! element's time a frame on decoded recordings at 720p and 1080p for each
//! interval, in interleaved rounds, beside the error each interval costs.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use gst::prelude::*;
use lsydrelight_testkit::{init, recording::score_recording};

use crate::{cpu_seconds, recording_dir};

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
pub(crate) fn reuse(rounds: usize, only: &[String]) -> Result<String, String> {
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
