//! Running a simulator recording through the real element and scoring it
//! against the recording's exact ground truth: the figures `evaluate_element`
//! records in the model card, the benchmark's, and what `tests/end_to_end.rs`
//! checks are all computed here.
//!
//! Every image scored, the element's output as much as its input and the
//! ground truth, is decoded to RGB by one decoder, `deskstage`'s
//! ([`ycbcr_planes_to_rgb`], the exact inverse of the simulator's writer and
//! the same as the trainer's `read_y4m`): the element's output is taken as the
//! Y'CbCr planes it wrote, never through `videoconvert`, whose 8-bit path maps
//! Y = 235 to 253 where deskstage's gives 255 and so moved the figures with no
//! change in the element.

use std::path::Path;
use std::time::Instant;

use deskstage::io::{Chroma, Y4mReader, ycbcr_planes_to_rgb};
use deskstage::monitor::RgbImage;
use gst::glib;
use gst::prelude::*;
use gst_video::prelude::*;

use crate::flow::{Gray, optical_flow, tof};
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
    /// The change error of the unrelit input: what the element's flicker is
    /// compared with. The input's frame-to-frame change carries the camera's
    /// noise and the screen's changing light, the truth's neither.
    pub input_change_rmse: f64,
    /// The change errors over the face region only, of the output and of the input.
    pub change_rmse_region: f64,
    pub input_change_rmse_region: f64,
    /// The face region's error split into two bands ([`Bands`]): the smooth
    /// band (the error blurred over [`DETAIL_RADIUS_FRACTION`] of the region)
    /// and the detail band (the rest), of the output and of the input.
    pub bands: Bands,
    pub input_bands: Bands,
    /// Sharpness: the RMS of the output's detail band over the truth's, in the
    /// face region. Below 1 the output is softer than the truth; the camera's
    /// noise, which the truth has not, raises it.
    pub detail_energy_ratio: f64,
    /// TecoGAN's tOF over the face region ([`crate::flow`]): the mean length, in
    /// pixels, of the difference between the output's optical flow from frame to
    /// frame and the ground truth's; and the same for the unrelit input. Computed
    /// when asked for (`with_flow`): classical flow takes a while.
    pub tof_region: Option<f64>,
    pub input_tof_region: Option<f64>,
    /// Share of adjacent frame pairs whose RMSE exceeds each of `ADJACENT_THRESHOLDS`
    /// (the paper's error rates).
    pub adjacent_over: Vec<f64>,
    /// Per-frame processing time of the pipeline, wall clock.
    pub ms_per_frame: f64,
    /// The element's `stats` at the end.
    pub stats: serde_json::Value,
}

/// RMSE on 0-255 of an error split into a smooth band and a detail band.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct Bands {
    pub smooth: f64,
    pub detail: f64,
}

/// Radius, as a fraction of the face region's side, of the two box blurs that
/// make an error's smooth band: 1/48, 7.5 pixels at 360 lines. Finer than the
/// gain field's finest shading (6% of the crop), so the detail band is what
/// the transfer carries over from the input as it is: the camera's noise, and
/// the source light's small shadows and highlights.
pub const DETAIL_RADIUS_FRACTION: f64 = 1.0 / 48.0;

/// Running sums of squares of the two bands of an error, and of the detail
/// bands of the two images compared.
#[derive(Default)]
struct BandSums {
    smooth: f64,
    detail: f64,
    detail_energy: [f64; 2],
    n: usize,
}

impl BandSums {
    /// Adds the error `a − b` over `region` (x, y, side).
    fn add(&mut self, a: &RgbImage, b: &RgbImage, (x0, y0, side): (usize, usize, usize)) {
        let radius = ((side as f64 * DETAIL_RADIUS_FRACTION).round() as usize).max(1);
        let smooth = |v: &[f64]| box_blur(&box_blur(v, side, radius), side, radius);
        for c in 0..3 {
            let [va, vb] = [a, b].map(|img| -> Vec<f64> {
                (0..side * side)
                    .map(|k| img.data[((y0 + k / side) * img.width + x0 + k % side) * 3 + c] as f64)
                    .collect()
            });
            let [sa, sb] = [smooth(&va), smooth(&vb)];
            for k in 0..side * side {
                let (da, db) = (va[k] - sa[k], vb[k] - sb[k]);
                self.smooth += (sa[k] - sb[k]).powi(2);
                self.detail += (da - db).powi(2);
                self.detail_energy[0] += da * da;
                self.detail_energy[1] += db * db;
            }
            self.n += side * side;
        }
    }

    fn rmse(&self) -> Bands {
        let n = self.n.max(1) as f64;
        Bands {
            smooth: (self.smooth / n).sqrt(),
            detail: (self.detail / n).sqrt(),
        }
    }
}

/// A box blur of a side × side map, `radius` each way, shrinking at the borders.
fn box_blur(field: &[f64], side: usize, radius: usize) -> Vec<f64> {
    let mut out = vec![0.0; field.len()];
    let mut prefix = vec![0.0; side + 1];
    // Along rows, then along columns of the result, each transposed on writing.
    let mut pass = |src: &[f64], dst: &mut [f64]| {
        for line in 0..side {
            for k in 0..side {
                prefix[k + 1] = prefix[k] + src[line * side + k];
            }
            for k in 0..side {
                let (lo, hi) = (k.saturating_sub(radius), (k + radius + 1).min(side));
                dst[k * side + line] = (prefix[hi] - prefix[lo]) / (hi - lo) as f64;
            }
        }
    };
    let mut rows = vec![0.0; field.len()];
    pass(field, &mut rows);
    pass(&rows, &mut out);
    out
}

/// Thresholds of the adjacent-frame error rates, RMSE on 0-255: the same as
/// `train/lsyd/evaluation/metrics.py`'s `TEMPORAL_THRESHOLDS`.
const ADJACENT_THRESHOLDS: [f64; 3] = [2.0, 4.0, 8.0];

/// A structure of numbers as JSON.
fn structure_json(s: &gst::StructureRef) -> serde_json::Value {
    let mut m = serde_json::Map::new();
    for (k, v) in s.iter() {
        let n = v
            .get::<u64>()
            .map(serde_json::Value::from)
            .or_else(|_| v.get::<f64>().map(serde_json::Value::from))
            .or_else(|_| v.get::<bool>().map(serde_json::Value::from))
            .unwrap_or(serde_json::Value::Null);
        m.insert(k.to_string(), n);
    }
    serde_json::Value::Object(m)
}

/// The region the scores call the face's: the frame's centred square (x, y, side).
fn face_square(frame: &RgbImage) -> (usize, usize, usize) {
    let size = frame.width.min(frame.height);
    ((frame.width - size) / 2, (frame.height - size) / 2, size)
}

/// The RMSE of `frames` against `truth`, frame by frame, over the region
/// [`Score::rmse_region`] reads: how frames made other than by the element
/// compare with its score.
pub fn face_region_rmse(frames: &[RgbImage], truth: &[RgbImage]) -> f64 {
    let (err, n) = frames
        .iter()
        .zip(truth)
        .map(|(frame, truth)| sq_err(frame, truth, Some(face_square(frame))))
        .fold((0.0, 0), |(e, n), (fe, fn_)| (e + fe, n + fn_));
    (err / n as f64).sqrt()
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

/// The change error of one frame pair: the RMSE, over `region` (x, y, side)
/// or the whole frame, of the change from `video.1` to `video.0` less the
/// change from `truth.1` to `truth.0`.
fn change_error(
    video: (&RgbImage, &RgbImage),
    truth: (&RgbImage, &RgbImage),
    region: Option<(usize, usize, usize)>,
) -> f64 {
    let (now, before) = video;
    let (x0, y0, size) = region.unwrap_or((0, 0, usize::MAX));
    let (mut sum, mut n) = (0.0, 0);
    for y in y0..(y0 + size).min(now.height) {
        for x in x0..(x0 + size).min(now.width) {
            let i = (y * now.width + x) * 3;
            for k in i..i + 3 {
                let d_video = now.data[k] as f64 - before.data[k] as f64;
                let d_truth = truth.0.data[k] as f64 - truth.1.data[k] as f64;
                sum += (d_video - d_truth) * (d_video - d_truth);
            }
            n += 3;
        }
    }
    (sum / n.max(1) as f64).sqrt()
}

/// What GStreamer should be told of deskstage's `.y4m` files: BT.601, limited
/// range, 4:2:0 chroma sited at the centre of each 2x2 block it averages. Their
/// header says `C420jpeg XCOLORRANGE=LIMITED`, but GStreamer 1.22's `y4mdec` reads
/// no colour tag nor the siting: it takes frames over 576 lines as BT.709 with
/// MPEG-2 siting, which the element would then decode with the wrong matrix.
const DESKSTAGE_Y4M: &str = "video/x-raw,colorimetry=bt601,chroma-site=jpeg";

/// A pipeline fragment that plays a deskstage `.y4m` file with its true colorimetry.
pub fn play_y4m(path: &Path) -> String {
    format!(
        "filesrc location=\"{}\" ! y4mdec ! capssetter caps=\"{DESKSTAGE_Y4M}\"",
        path.display()
    )
}

/// A frame of the Y'CbCr video deskstage writes (I420 or Y444, BT.601 limited
/// range), decoded as [`Y4mReader`] decodes the files.
fn sample_to_image(sample: &gst::Sample) -> Result<RgbImage, String> {
    let caps = sample.caps().ok_or("a sample without caps")?;
    let info = gst_video::VideoInfo::from_caps(caps).map_err(|e| e.to_string())?;
    let chroma = match info.format() {
        gst_video::VideoFormat::I420 => Chroma::C420,
        gst_video::VideoFormat::Y444 => Chroma::C444,
        _ => {
            return Err(format!(
                "scoring reads I420 or Y444 as deskstage writes, not {caps}"
            ));
        }
    };
    let colorimetry = info.colorimetry();
    if colorimetry.matrix() != gst_video::VideoColorMatrix::Bt601
        || colorimetry.range() != gst_video::VideoColorRange::Range16_235
    {
        return Err(format!(
            "scoring decodes BT.601 limited range as deskstage writes, not {colorimetry}"
        ));
    }
    let buffer = sample.buffer().ok_or("a sample without a buffer")?;
    let frame = gst_video::VideoFrameRef::from_buffer_ref_readable(buffer, &info)
        .map_err(|e| e.to_string())?;
    let (w, h) = (info.width() as usize, info.height() as usize);
    // Each plane without its row padding, as the file stores it.
    let plane = |p: u32| -> Result<Vec<u8>, String> {
        let (pw, ph) = match chroma {
            Chroma::C420 if p > 0 => (w / 2, h / 2),
            _ => (w, h),
        };
        let stride = frame.plane_stride()[p as usize] as usize;
        let data = frame.plane_data(p).map_err(|e| e.to_string())?;
        Ok((0..ph)
            .flat_map(|row| &data[row * stride..row * stride + pw])
            .copied()
            .collect())
    };
    Ok(ycbcr_planes_to_rgb(
        &plane(0)?,
        &plane(1)?,
        &plane(2)?,
        w,
        h,
        chroma,
    ))
}

fn launch(description: &str) -> Result<gst::Pipeline, String> {
    gst::parse::launch(description)
        .map_err(|e| e.to_string())?
        .downcast::<gst::Pipeline>()
        .map_err(|_| "not a pipeline".to_string())
}

/// Relights `<dir>/face.y4m` (with `<dir>/monitor.y4m` unless `with_monitor` is false)
/// to the target `<dir>/target-<target>.png` and scores it against `<dir>/truth-<target>.y4m`.
/// The element relights with the person's own model (`models/default`); `properties`
/// are set on it from strings, as gst-launch does (a name or value it refuses is an
/// error); `with_flow` adds the flow-based tOF.
pub fn score_recording(
    dir: &Path,
    target: &str,
    with_monitor: bool,
    properties: &[(&str, &str)],
    with_flow: bool,
) -> Result<Score, String> {
    score_face(
        dir,
        &dir.join("face.y4m"),
        target,
        with_monitor,
        properties,
        with_flow,
    )
}

/// [`score_recording`] with another face video in place of `<dir>/face.y4m`:
/// the recording's noiseless face ([`ensure_clean_face`]), to tell what in the
/// error comes from the camera's noise and what from the source light.
pub fn score_face(
    dir: &Path,
    face: &Path,
    target: &str,
    with_monitor: bool,
    properties: &[(&str, &str)],
    with_flow: bool,
) -> Result<Score, String> {
    init();
    let monitor = if with_monitor {
        format!(
            "{} ! queue max-size-buffers=4 ! r.monitor_sink",
            play_y4m(&dir.join("monitor.y4m"))
        )
    } else {
        String::new()
    };
    let pipeline = launch(&format!(
        "lsydrelight name=r {} ! queue max-size-buffers=4 ! r.sink {monitor} \
         r.src ! appsink name=out sync=false",
        play_y4m(face)
    ))?;
    let r = pipeline.by_name("r").ok_or("no element r")?;
    r.set_property(
        "target-location",
        dir.join(format!("target-{target}.png")).to_str().unwrap(),
    );
    // The recordings are of the simulator's default person: relight them with
    // their own model unless `properties` say otherwise.
    r.set_property(
        "model-location",
        crate::default_model().to_str().expect("UTF-8 path"),
    );
    set_properties(&r, properties)?;
    score_pipeline(
        &pipeline,
        face,
        &dir.join(format!("truth-{target}.y4m")),
        Some(&r),
        with_flow,
    )
}

/// An element property setting given on a command line as NAME=VALUE (`--set`),
/// split at the first `=`.
pub fn property_setting(text: &str) -> Result<(String, String), String> {
    text.split_once('=')
        .map(|(name, value)| (name.to_string(), value.to_string()))
        .ok_or_else(|| format!("--set {text}: give NAME=VALUE, such as alpha=1"))
}

/// Sets each NAME=VALUE of `properties` ([`property_setting`]) on the element,
/// or says which one it refuses and why.
pub fn set_properties<N: AsRef<str>, V: AsRef<str>>(
    element: &gst::Element,
    properties: &[(N, V)],
) -> Result<(), String> {
    properties
        .iter()
        .try_for_each(|(k, v)| set_from_str(element, k.as_ref(), v.as_ref()))
}

/// Sets the element's property `name` from `value` as gst-launch would, or says
/// what is wrong (glib's own setter panics on a value the property refuses).
fn set_from_str(element: &gst::Element, name: &str, value: &str) -> Result<(), String> {
    let pspec = element.find_property(name).ok_or_else(|| {
        format!("lsydrelight has no property {name} (gst-inspect-1.0 lsydrelight lists them)")
    })?;
    if !pspec.flags().contains(glib::ParamFlags::WRITABLE) {
        return Err(format!(
            "lsydrelight's {name} cannot be set: it is read-only"
        ));
    }
    let parsed = glib::Value::deserialize_with_pspec(value, &pspec)
        .ok()
        .filter(|parsed| within_range(&pspec, parsed))
        .ok_or_else(|| {
            format!("lsydrelight's {name} does not take {value} (gst-inspect-1.0 lsydrelight gives its type and range)")
        })?;
    element.set_property_from_value(name, &parsed);
    Ok(())
}

/// Whether a numeric property's `value` lies within its declared range (other
/// kinds of value were checked when they were parsed).
fn within_range(pspec: &glib::ParamSpec, value: &glib::Value) -> bool {
    macro_rules! range_of {
        ($spec:ty, $number:ty) => {
            if let Some(spec) = pspec.downcast_ref::<$spec>() {
                return value
                    .get::<$number>()
                    .is_ok_and(|v| (spec.minimum()..=spec.maximum()).contains(&v));
            }
        };
    }
    range_of!(glib::ParamSpecDouble, f64);
    range_of!(glib::ParamSpecFloat, f32);
    range_of!(glib::ParamSpecInt, i32);
    range_of!(glib::ParamSpecUInt, u32);
    range_of!(glib::ParamSpecInt64, i64);
    range_of!(glib::ParamSpecUInt64, u64);
    true
}

/// Scores the face video `face` as it is, through the same pipeline and decoding
/// as the element's output but without the element, against `truth`: how the
/// harness checks itself (a video scored against itself is 0 everywhere).
pub fn score_unrelit(face: &Path, truth: &Path) -> Result<Score, String> {
    init();
    let pipeline = launch(&format!(
        "{} ! queue max-size-buffers=4 ! appsink name=out sync=false",
        play_y4m(face)
    ))?;
    score_pipeline(&pipeline, face, truth, None, false)
}

/// Plays `pipeline`, whose appsink `out` gives the frames to score, and scores
/// them against `truth`, and `input` (what went in) against it too. `element`'s
/// `stats` go into the score.
fn score_pipeline(
    pipeline: &gst::Pipeline,
    input: &Path,
    truth: &Path,
    element: Option<&gst::Element>,
    with_flow: bool,
) -> Result<Score, String> {
    let sink = pipeline
        .by_name("out")
        .ok_or("no appsink")?
        .downcast::<gst_app::AppSink>()
        .map_err(|_| "not an appsink")?;
    let mut truth = Y4mReader::open(truth).map_err(|e| e.to_string())?;
    let mut input = Y4mReader::open(input).map_err(|e| e.to_string())?;
    pipeline
        .set_state(gst::State::Playing)
        .map_err(|e| format!("cannot play: {e}"))?;

    let mut score = Score::default();
    let (mut region_err, mut region_n, mut frame_err, mut frame_n, mut in_err) =
        (0.0, 0, 0.0, 0, 0.0);
    let mut previous: Option<[RgbImage; 3]> = None;
    let mut adjacent = Vec::new();
    let (mut change, mut input_change) = (0.0, 0.0);
    let (mut change_region, mut input_change_region) = (0.0, 0.0);
    let (mut bands, mut input_bands) = (BandSums::default(), BandSums::default());
    // The face regions of the last output, truth and input, and the tOF sums.
    let mut previous_luma: Option<[Gray; 3]> = None;
    let (mut tof_out, mut tof_in, mut tof_pairs) = (0.0, 0.0, 0);
    // Time spent on the flow, which is not the pipeline's.
    let mut flow_time = std::time::Duration::ZERO;
    let started = Instant::now();
    let result = loop {
        let Some(sample) = sink.try_pull_sample(gst::ClockTime::from_seconds(120)) else {
            break if sink.is_eos() {
                Ok(())
            } else {
                Err("no frame within 120 s".to_string())
            };
        };
        // Errors break out of the loop, so that the pipeline is stopped below.
        let (out, gt, inp) = match (
            sample_to_image(&sample),
            truth.next_frame(),
            input.next_frame(),
        ) {
            (Ok(out), Ok(Some(gt)), Ok(Some(inp))) => (out, gt, inp),
            (Err(e), _, _) => break Err(e),
            (_, Ok(None), _) => break Err("more relit frames than ground-truth frames".into()),
            (_, _, Ok(None)) => break Err("more relit frames than input frames".into()),
            (_, Err(e), _) | (_, _, Err(e)) => break Err(e.to_string()),
        };
        let face = face_square(&out);
        let (e, n) = sq_err(&out, &gt, Some(face));
        region_err += e;
        region_n += n;
        in_err += sq_err(&inp, &gt, Some(face)).0;
        let (e, n) = sq_err(&out, &gt, None);
        frame_err += e;
        frame_n += n;
        bands.add(&out, &gt, face);
        input_bands.add(&inp, &gt, face);
        if let Some([po, pg, pi]) = &previous {
            let a: f64 = (out.data.iter().zip(&po.data))
                .map(|(&o, &p)| (o as f64 - p as f64).powi(2))
                .sum();
            adjacent.push((a / out.data.len() as f64).sqrt());
            change += change_error((&out, po), (&gt, pg), None);
            input_change += change_error((&inp, pi), (&gt, pg), None);
            change_region += change_error((&out, po), (&gt, pg), Some(face));
            input_change_region += change_error((&inp, pi), (&gt, pg), Some(face));
        }
        if with_flow {
            let flow_started = Instant::now();
            let luma = [&out, &gt, &inp].map(|img| Gray::luma(img, face));
            if let Some([po, pg, pi]) = &previous_luma {
                let truth_flow = optical_flow(pg, &luma[1]);
                tof_out += tof((po, &luma[0]), &truth_flow);
                tof_in += tof((pi, &luma[2]), &truth_flow);
                tof_pairs += 1;
            }
            previous_luma = Some(luma);
            flow_time += flow_started.elapsed();
        }
        previous = Some([out, gt, inp]);
        score.frames += 1;
    };
    let elapsed = started.elapsed().saturating_sub(flow_time);
    if let Some(element) = element {
        score.stats = structure_json(&element.property::<gst::Structure>("stats"));
    }
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
    let pairs = (score.frames - 1).max(1) as f64;
    score.change_rmse = change / pairs;
    score.input_change_rmse = input_change / pairs;
    score.change_rmse_region = change_region / pairs;
    score.input_change_rmse_region = input_change_region / pairs;
    score.bands = bands.rmse();
    score.detail_energy_ratio = (bands.detail_energy[0] / bands.detail_energy[1].max(1e-9)).sqrt();
    score.input_bands = input_bands.rmse();
    if with_flow && tof_pairs > 0 {
        score.tof_region = Some(tof_out / tof_pairs as f64);
        score.input_tof_region = Some(tof_in / tof_pairs as f64);
    }
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

/// The noiseless face of the standard recording `name`'s first `frames` frames,
/// rendered once into `target/clean-faces/`.
pub fn clean_face_of(name: &str, frames: usize) -> Result<std::path::PathBuf, String> {
    let path = crate::checkout().join(format!("target/clean-faces/{name}-{frames}.y4m"));
    ensure_clean_face(&path, name, frames)?;
    Ok(path)
}

/// Writes `path`, the first `frames` frames of the standard recording `name`
/// as the webcam would have filmed them without sensor noise (4:2:0, as
/// `face.y4m`); skipped when present. Rendered apart from the recording (only
/// the source light, about half a second a frame) so that recordings already
/// rendered need not be again.
pub fn ensure_clean_face(path: &Path, name: &str, frames: usize) -> Result<(), String> {
    if path.exists() {
        return Ok(());
    }
    let mut spec = deskstage::dataset::RecordingSpec::standard(name).ok_or("unknown recording")?;
    spec.frames = frames;
    let rec = deskstage::dataset::Recording::new(spec)?;
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| e.to_string())?;
    }
    let partial = path.with_extension("partial");
    let s = &rec.spec;
    let mut w = deskstage::io::Y4mWriter::create(&partial, s.width, s.height, s.fps, Chroma::C420)
        .map_err(|e| e.to_string())?;
    for i in 0..frames {
        w.write(&rec.frame(i, false).clean_face)
            .map_err(|e| e.to_string())?;
    }
    w.finish().map_err(|e| e.to_string())?;
    std::fs::rename(&partial, path).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use deskstage::io::Y4mWriter;

    use super::*;

    /// Two frames of saturated colours, greys and white, as deskstage would write them.
    fn write_pattern(path: &Path, width: usize, height: usize, chroma: Chroma) {
        let mut w = Y4mWriter::create(path, width, height, 30, chroma).unwrap();
        for frame in 0..2 {
            let mut img = RgbImage::new(width, height);
            for (i, px) in img.data.chunks_exact_mut(3).enumerate() {
                let (x, y) = (i % width, i / width);
                px.copy_from_slice(&[
                    (x * 255 / width) as u8,
                    (y * 255 / height) as u8,
                    if (x / 16 + y / 16 + frame) % 2 == 0 {
                        255
                    } else {
                        0
                    },
                ]);
            }
            w.write(&img).unwrap();
        }
        w.finish().unwrap();
    }

    #[test]
    fn a_video_scored_against_itself_is_zero_at_any_size() {
        let dir = std::env::temp_dir().join(format!("testkit-y4m-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // 720 lines is where y4mdec would take the files as BT.709 unless told.
        for (width, height, chroma) in [
            (480, 360, Chroma::C420),
            (1280, 720, Chroma::C420),
            (1280, 720, Chroma::C444),
        ] {
            let path = dir.join(format!("{width}x{height}-{chroma:?}.y4m"));
            write_pattern(&path, width, height, chroma);
            let s = score_unrelit(&path, &path)
                .unwrap_or_else(|e| panic!("{width}x{height} {chroma:?}: {e}"));
            assert_eq!(s.frames, 2);
            assert_eq!(
                (s.rmse_frame, s.rmse_region, s.input_rmse_region),
                (0.0, 0.0, 0.0),
                "{width}x{height} {chroma:?}: the played frames and the read ones differ"
            );
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
