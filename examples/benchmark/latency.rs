//! Per-frame latency through the element at a frame size, one frame in
//! flight, with the element's own figures by stage: what the full run's
//! latency variants and `--stages` time.

use std::sync::{Arc, Mutex};
use std::time::Instant;

use gst::prelude::*;
use lsydrelight_testkit::init;
use serde::{Deserialize, Serialize};

use crate::full_run::{Variant, properties};

#[derive(Debug, Default, Serialize, Deserialize)]
pub(crate) struct LatencyResult {
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) format: String,
    pub(crate) frames: usize,
    /// From a frame entering the element's face pad to it leaving `src`, one frame
    /// in flight at a time.
    pub(crate) p50_ms: f64,
    pub(crate) p99_ms: f64,
    pub(crate) fps: f64,
    /// Mean milliseconds a frame, from the element's statistics: in all, in ONNX
    /// Runtime, reading the face region (crop, conversion, resampling), putting the
    /// lighting change back, averaging and smoothing, and reading monitor frames.
    pub(crate) processing_ms: f64,
    pub(crate) network_ms: f64,
    pub(crate) crop_ms: f64,
    pub(crate) paste_ms: f64,
    pub(crate) smoothing_ms: f64,
    pub(crate) monitor_light_ms: f64,
    /// The rest, by stage (the element's `stats`): following the face, building
    /// the lighting change, the policy's deciding, the element's setup and finish,
    /// and the whole turn of a frame in the element up to handing it downstream.
    #[serde(default)]
    pub(crate) follow_ms: f64,
    #[serde(default)]
    pub(crate) change_ms: f64,
    #[serde(default)]
    pub(crate) decide_ms: f64,
    #[serde(default)]
    pub(crate) setup_ms: f64,
    #[serde(default)]
    pub(crate) finish_ms: f64,
    #[serde(default)]
    pub(crate) frame_ms: f64,
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

pub(crate) fn latency(
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
