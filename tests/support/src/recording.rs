//! Running a simulator recording through the real element and scoring it
//! against the recording's exact ground truth: the figures `evaluate_element`
//! records in the model card, the benchmark's, and what `tests/end_to_end.rs`
//! checks are all computed here.

use std::path::Path;
use std::time::Instant;

use deskstage::io::Y4mReader;
use deskstage::monitor::RgbImage;
use gst::prelude::*;
use gst_video::prelude::*;

use crate::init;

/// Errors of the whole frame and of the face region, against ground truth.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Score {
    pub frames: usize,
    /// RMSE on 0-255 over the element's face region (the centred square).
    pub rmse_region: f64,
    /// RMSE on 0-255 over the whole frame.
    pub rmse_frame: f64,
    /// The same for the unrelit input: how much relighting had to change.
    pub input_rmse_region: f64,
    /// Adjacent-frame RMSE of the output, and of the change against the ground truth's change.
    pub adjacent_rmse: f64,
    pub change_rmse: f64,
    /// Share of adjacent frame pairs whose RMSE exceeds each of `ADJACENT_THRESHOLDS`
    /// (the paper's error rates).
    pub adjacent_over: Vec<f64>,
    /// Per-frame processing time of the pipeline, wall clock.
    pub ms_per_frame: f64,
    /// The element's `stats` at the end.
    pub stats: serde_json::Value,
}

/// Thresholds of the adjacent-frame error rates, RMSE on 0-255: the same as
/// `train/lsyd/metrics.py`'s `TEMPORAL_THRESHOLDS`.
const ADJACENT_THRESHOLDS: [f64; 3] = [2.0, 4.0, 8.0];

/// A structure of numbers as JSON.
fn structure_json(s: &gst::StructureRef) -> serde_json::Value {
    let mut m = serde_json::Map::new();
    for (k, v) in s.iter() {
        let n = v
            .get::<u64>()
            .map(serde_json::Value::from)
            .or_else(|_| v.get::<f64>().map(serde_json::Value::from))
            .unwrap_or(serde_json::Value::Null);
        m.insert(k.to_string(), n);
    }
    serde_json::Value::Object(m)
}

fn sq_err(a: &RgbImage, b: &RgbImage, region: Option<(usize, usize, usize)>) -> (f64, usize) {
    let (x0, y0, size) = region.unwrap_or((0, 0, usize::MAX));
    let mut sum = 0.0;
    let mut n = 0;
    for y in y0..(y0 + size).min(a.height) {
        for x in x0..(x0 + size).min(a.width) {
            let i = (y * a.width + x) * 3;
            for c in 0..3 {
                let d = a.data[i + c] as f64 - b.data[i + c] as f64;
                sum += d * d;
            }
            n += 3;
        }
    }
    (sum, n)
}

fn sample_to_image(sample: &gst::Sample) -> RgbImage {
    let caps = sample.caps().expect("caps");
    let info = gst_video::VideoInfo::from_caps(caps).expect("video caps");
    let buffer = sample.buffer().expect("buffer");
    let frame = gst_video::VideoFrameRef::from_buffer_ref_readable(buffer, &info).expect("map");
    let (w, h) = (info.width() as usize, info.height() as usize);
    let stride = frame.plane_stride()[0] as usize;
    let data = frame.plane_data(0).expect("plane");
    let mut img = RgbImage::new(w, h);
    for y in 0..h {
        img.data[y * w * 3..(y + 1) * w * 3].copy_from_slice(&data[y * stride..y * stride + w * 3]);
    }
    img
}

/// Relights `<dir>/face.y4m` (with `<dir>/monitor.y4m` unless `with_monitor` is false)
/// to the target `<dir>/target-<target>.png` and scores it against `<dir>/truth-<target>.y4m`.
/// `properties` are set on the element from strings, as gst-launch does.
pub fn score_recording(
    dir: &Path,
    target: &str,
    with_monitor: bool,
    properties: &[(&str, &str)],
) -> Result<Score, String> {
    init();
    let monitor = if with_monitor {
        format!(
            "filesrc location={} ! y4mdec ! queue max-size-buffers=4 ! r.monitor_sink",
            dir.join("monitor.y4m").display()
        )
    } else {
        String::new()
    };
    let desc = format!(
        "lsydrelight name=r filesrc location={} ! y4mdec ! queue max-size-buffers=4 ! r.sink {monitor} \
         r.src ! videoconvert ! video/x-raw,format=RGB ! appsink name=out sync=false",
        dir.join("face.y4m").display()
    );
    let pipeline = gst::parse::launch(&desc)
        .map_err(|e| e.to_string())?
        .downcast::<gst::Pipeline>()
        .map_err(|_| "not a pipeline")?;
    let r = pipeline.by_name("r").ok_or("no element r")?;
    r.set_property(
        "target-location",
        dir.join(format!("target-{target}.png")).to_str().unwrap(),
    );
    for (k, v) in properties {
        r.set_property_from_str(k, v);
    }
    let sink = pipeline
        .by_name("out")
        .ok_or("no appsink")?
        .downcast::<gst_app::AppSink>()
        .map_err(|_| "not an appsink")?;
    let mut truth =
        Y4mReader::open(&dir.join(format!("truth-{target}.y4m"))).map_err(|e| e.to_string())?;
    let mut input = Y4mReader::open(&dir.join("face.y4m")).map_err(|e| e.to_string())?;
    pipeline
        .set_state(gst::State::Playing)
        .map_err(|e| format!("cannot play: {e}"))?;

    let mut score = Score::default();
    let (mut region_err, mut region_n, mut frame_err, mut frame_n, mut in_err) =
        (0.0, 0, 0.0, 0, 0.0);
    let mut previous: Option<(RgbImage, RgbImage)> = None;
    let mut adjacent = Vec::new();
    let mut change = 0.0;
    let started = Instant::now();
    let result = loop {
        let Some(sample) = sink.try_pull_sample(gst::ClockTime::from_seconds(120)) else {
            break if sink.is_eos() {
                Ok(())
            } else {
                Err("no frame within 120 s".to_string())
            };
        };
        let out = sample_to_image(&sample);
        let Some(gt) = truth.next_frame().map_err(|e| e.to_string())? else {
            break Err("more relit frames than ground-truth frames".into());
        };
        let inp = input
            .next_frame()
            .map_err(|e| e.to_string())?
            .ok_or("input ended early")?;
        let size = out.width.min(out.height);
        let region = Some(((out.width - size) / 2, (out.height - size) / 2, size));
        let (e, n) = sq_err(&out, &gt, region);
        region_err += e;
        region_n += n;
        in_err += sq_err(&inp, &gt, region).0;
        let (e, n) = sq_err(&out, &gt, None);
        frame_err += e;
        frame_n += n;
        if let Some((po, pg)) = &previous {
            let mut a = 0.0;
            let mut c = 0.0;
            for i in 0..out.data.len() {
                let d_out = out.data[i] as f64 - po.data[i] as f64;
                let d_gt = gt.data[i] as f64 - pg.data[i] as f64;
                a += d_out * d_out;
                c += (d_out - d_gt) * (d_out - d_gt);
            }
            adjacent.push((a / out.data.len() as f64).sqrt());
            change += (c / out.data.len() as f64).sqrt();
        }
        previous = Some((out, gt));
        score.frames += 1;
    };
    let elapsed = started.elapsed();
    score.stats = structure_json(&r.property::<gst::Structure>("stats"));
    let bus_error = pipeline
        .bus()
        .and_then(|b| b.pop_filtered(&[gst::MessageType::Error]));
    pipeline
        .set_state(gst::State::Null)
        .map_err(|e| e.to_string())?;
    if let Some(m) = bus_error
        && let gst::MessageView::Error(e) = m.view()
    {
        return Err(format!("pipeline error: {} ({:?})", e.error(), e.debug()));
    }
    result?;
    if score.frames == 0 {
        return Err("the pipeline produced no frames".into());
    }
    score.rmse_region = (region_err / region_n as f64).sqrt();
    score.input_rmse_region = (in_err / region_n as f64).sqrt();
    score.rmse_frame = (frame_err / frame_n as f64).sqrt();
    score.adjacent_rmse = adjacent.iter().sum::<f64>() / adjacent.len().max(1) as f64;
    score.adjacent_over = ADJACENT_THRESHOLDS
        .iter()
        .map(|t| adjacent.iter().filter(|a| *a > t).count() as f64 / adjacent.len().max(1) as f64)
        .collect();
    score.change_rmse = change / (score.frames - 1).max(1) as f64;
    score.ms_per_frame = elapsed.as_secs_f64() * 1e3 / score.frames as f64;
    Ok(score)
}

/// Renders a standard recording's first `frames` frames into `dir` (skipped when present).
pub fn ensure_recording(dir: &Path, name: &str, frames: usize) -> Result<(), String> {
    let marker = dir.join("meta.json");
    if marker.exists() {
        let meta: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&marker).map_err(|e| e.to_string())?)
                .map_err(|e| e.to_string())?;
        if meta["spec"]["frames"] == frames && meta["spec"]["name"] == name {
            return Ok(());
        }
    }
    let mut spec = deskstage::dataset::RecordingSpec::standard(name).ok_or("unknown recording")?;
    spec.frames = frames;
    let rec = deskstage::dataset::Recording::new(spec)?;
    rec.write(dir).map_err(|e| e.to_string())
}
