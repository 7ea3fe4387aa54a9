//! The prepare stage: each session's camera recording decoded, the face found
//! and cropped exactly as the element does (its face detector, tracker and the
//! model contract's crop rule, its frame views and area resampling), resized to
//! the trainer's capture size, and written in the trainer's session format with
//! the screen light of each frame:
//!
//! ```text
//! <dest>/<session>/face.npy        (N, 256, 256, 3) uint8, sRGB
//!                  timestamps.npy  (N,) float64, seconds (the camera's running time)
//!                  lights.npy      (N, 3, 16, 32) float32, the light on the face at each frame
//!                  meta.json       counts, and what the frames were made with
//! ```
//!
//! A frame is kept when the tracker follows a face at full weight (no fade) and
//! a screen frame was shown at or before it. At most `fps` frames a second are
//! kept: neighbouring webcam frames add little but disk. A session already
//! prepared with the same inputs and settings is not prepared again.

use std::fs::File;
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Instant, UNIX_EPOCH};

use deskstage::io::{NpyWriter, write_npy};
use gst::prelude::*;
use gstlsydrelight::engine::runtime;
use gstlsydrelight::face::{CropRule, FaceDetector, FaceTracker, TrackerSettings};
use gstlsydrelight::frame::sample_crop;
use gstlsydrelight::light::{LIGHT_COLS, LIGHT_LEN, LIGHT_ROWS};
use gstlsydrelight::lsydrelight::video;
use gstlsydrelight::paths;

use super::capture::{Captures, HELD_OUT_SHARE, HeldOut, Session};
use crate::exit::Failure;
use crate::interrupt;
use crate::progress::Bars;

/// Side of the face crops written: the trainer's capture size (`capture_import.SIZE`).
pub const CAPTURE_SIZE: usize = 256;

#[derive(Clone, Copy, Debug)]
pub struct Settings {
    /// Seconds by which the screen's content precedes its light on the face.
    pub offset: f64,
    /// Frames kept a second, at most.
    pub fps: f64,
    /// The model contract's crop rule.
    pub crop: CropRule,
}

/// What became of one session's frames.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize, PartialEq)]
pub struct Counts {
    pub decoded: u64,
    /// Kept for training (or for the held-out set).
    pub kept: u64,
    pub held_out: u64,
    /// Not followed at full weight by the face tracker.
    pub no_face: u64,
    /// Before the first screen frame.
    pub no_light: u64,
    /// Skipped to keep at most `fps` a second.
    pub thinned: u64,
}

/// Where a session's frames go: the training data, the held-out set, or split at a time.
enum Route {
    Train,
    HeldOut,
    SplitAt(f64),
}

/// Prepares every session into `work/data/captures` and `work/heldout`.
pub fn run(
    captures: &Captures,
    work: &Path,
    settings: Settings,
    bars: &Bars,
) -> Result<Vec<(String, Counts)>, Failure> {
    let library = paths::default_ort_library();
    let env = runtime::environment(&library).map_err(|e| Failure::new(e.to_string()))?;
    let detector_path = paths::default_face_detector();
    let mut detector = FaceDetector::new(env, &detector_path, 2).map_err(|e| {
        Failure::new(format!(
            "{e}; run from the lsydrelight checkout, which ships models/face"
        ))
    })?;
    let mut reports = Vec::new();
    for (i, session) in captures.sessions.iter().enumerate() {
        let route = match captures.held_out {
            HeldOut::Session(h) if h == i => Route::HeldOut,
            HeldOut::Session(_) => Route::Train,
            HeldOut::TailOfOnly => {
                let (first, last) = (session.light_times[0], session.light_times.last().copied());
                let last = last.unwrap_or(first);
                Route::SplitAt(first + (1.0 - HELD_OUT_SHARE) * (last - first))
            }
        };
        let counts = prepare_session(session, &route, work, settings, &mut detector, bars)?;
        if counts.kept == 0 {
            return Err(Failure::new(format!(
                "{}: no usable frame: of {} frames decoded, {} had no face the detector \
                 followed and {} came before the first screen frame; check that the camera \
                 sees your face, well lit, and record the session again",
                session.dir.display(),
                counts.decoded,
                counts.no_face,
                counts.no_light
            )));
        }
        reports.push((session.label.clone(), counts));
    }
    Ok(reports)
}

/// Folder name of a session in the work folder: its label with `/` as `-`.
fn folder_name(session: &Session) -> String {
    session.label.replace(['/', '\\'], "-")
}

/// What a prepared session was made from; a session is prepared again when it differs.
fn fingerprint(session: &Session, settings: Settings, part: &str) -> serde_json::Value {
    let meta = std::fs::metadata(session.camera()).ok();
    let modified = meta
        .as_ref()
        .and_then(|m| m.modified().ok())
        .and_then(|t| t.duration_since(UNIX_EPOCH).ok())
        .map(|d| d.as_nanos() as u64);
    serde_json::json!({
        "camera": session.camera().canonicalize().unwrap_or_else(|_| session.camera()),
        "camera_bytes": meta.map(|m| m.len()),
        "camera_modified_ns": modified,
        "lights": session.light_times.len(),
        "offset": settings.offset,
        "fps": settings.fps,
        "crop": {"side": settings.crop.side, "lift": settings.crop.lift},
        "size": CAPTURE_SIZE,
        "part": part,
    })
}

fn already_prepared(dir: &Path, fingerprint: &serde_json::Value) -> Option<Counts> {
    let text = std::fs::read_to_string(dir.join("meta.json")).ok()?;
    let meta: serde_json::Value = serde_json::from_str(&text).ok()?;
    (meta.get("prepared_from")? == fingerprint)
        .then(|| serde_json::from_value(meta.get("counts")?.clone()).ok())
        .flatten()
}

fn prepare_session(
    session: &Session,
    route: &Route,
    work: &Path,
    settings: Settings,
    detector: &mut FaceDetector,
    bars: &Bars,
) -> Result<Counts, Failure> {
    let name = folder_name(session);
    let train_dir = work.join("data/captures").join(&name);
    let held_dir = work.join("heldout").join(&name);
    let outputs: Vec<(PathBuf, &str)> = match route {
        Route::Train => vec![(train_dir, "all")],
        Route::HeldOut => vec![(held_dir, "all")],
        Route::SplitAt(_) => vec![(train_dir, "before split"), (held_dir, "after split")],
    };
    let prints: Vec<_> = outputs
        .iter()
        .map(|(_, part)| fingerprint(session, settings, part))
        .collect();
    let done: Vec<_> = outputs
        .iter()
        .zip(&prints)
        .map(|((dir, _), p)| already_prepared(dir, p))
        .collect();
    if let Some(Some(counts)) = done.iter().all(Option::is_some).then(|| done[0].clone()) {
        // Every part records the whole session's counts.
        bars.note(&format!("  {}: prepared before, kept", session.label));
        return Ok(counts);
    }
    let mut writers = outputs
        .iter()
        .map(|(dir, _)| SessionWriter::create(dir))
        .collect::<Result<Vec<_>, _>>()?;

    let mut tracker = FaceTracker::new(TrackerSettings {
        crop: settings.crop,
        ..TrackerSettings::default()
    });
    let mut counts = Counts::default();
    let mut last_kept = f64::NEG_INFINITY;
    let bar = bars.add(&format!("  {}", session.label));
    let started = Instant::now();
    let mut failure = None;
    decode(&session.camera(), &mut |frame, time| {
        counts.decoded += 1;
        bar.update(counts.decoded, || session.camera_frames);
        let tracked = match tracker.track(&frame, time, |f| detector.detect(f)) {
            Ok(t) => t,
            Err(e) => {
                failure = Some(Failure::new(format!("the face detector failed: {e}")));
                return false;
            }
        };
        if tracked.fade < 1.0 || tracked.face.is_none() {
            counts.no_face += 1;
            return true;
        }
        let Some(light) = session.light_at(time, settings.offset) else {
            counts.no_light += 1;
            return true;
        };
        if time < last_kept + 1.0 / settings.fps - 1e-6 {
            counts.thinned += 1;
            return true;
        }
        last_kept = time;
        let crop = sample_crop(
            &frame,
            tracked.square.crop(frame.width, frame.height),
            CAPTURE_SIZE,
        );
        let (writer, held) = match route {
            Route::Train => (&mut writers[0], false),
            Route::HeldOut => (&mut writers[0], true),
            Route::SplitAt(t) if time < *t => (&mut writers[0], false),
            Route::SplitAt(_) => (&mut writers[1], true),
        };
        if let Err(e) = writer.push(&crop, time, session.light(light)) {
            failure = Some(e);
            return false;
        }
        counts.kept += 1;
        counts.held_out += held as u64;
        !interrupt::stop_requested()
    })?;
    bar.finish();
    if let Some(f) = failure {
        return Err(f);
    }
    if interrupt::stop_requested() {
        return Err(Failure::new("stopped"));
    }
    for ((writer, (_, part)), print) in writers.into_iter().zip(&outputs).zip(prints) {
        writer.finish(session, part, &counts, print)?;
    }
    bars.note(&format!(
        "  {}: {} frames decoded in {:.1} s, {} kept ({} held out), {} without a followed face, {} before the first screen frame, {} thinned to {} a second",
        session.label,
        counts.decoded,
        started.elapsed().as_secs_f64(),
        counts.kept,
        counts.held_out,
        counts.no_face,
        counts.no_light,
        counts.thinned,
        settings.fps
    ));
    Ok(counts)
}

/// Decodes `path` and calls `each(frame, seconds)` on every video frame, in the
/// formats the element takes, until it returns false or the stream ends.
fn decode(
    path: &Path,
    each: &mut dyn FnMut(gstlsydrelight::frame::Frame, f64) -> bool,
) -> Result<(), Failure> {
    let location = path
        .to_str()
        .ok_or_else(|| Failure::new(format!("{}: the path is not UTF-8", path.display())))?;
    let pipeline = gst::Pipeline::new();
    let make = |factory: &str| {
        gst::ElementFactory::make(factory).build().map_err(|_| {
            Failure::new(format!(
                "the GStreamer element {factory} is missing; install gstreamer1.0-plugins-base and -good"
            ))
        })
    };
    let src = make("filesrc")?;
    src.set_property("location", location);
    let decodebin = make("decodebin")?;
    let convert = make("videoconvert")?;
    let sink = gst_app::AppSink::builder()
        .caps(&video::face_caps())
        .sync(false)
        .max_buffers(4)
        .build();
    pipeline
        .add_many([&src, &decodebin, &convert, sink.upcast_ref()])
        .and_then(|_| src.link(&decodebin))
        .and_then(|_| gst::Element::link_many([&convert, sink.upcast_ref()]))
        .map_err(|e| Failure::new(format!("internal error: decode pipeline: {e}")))?;
    let convert_sink = convert.static_pad("sink");
    decodebin.connect_pad_added(move |_, pad| {
        let is_video = pad
            .current_caps()
            .and_then(|c| c.structure(0).map(|s| s.name().starts_with("video/")))
            .unwrap_or(false);
        if let Some(sink) = convert_sink.as_ref().filter(|s| is_video && !s.is_linked()) {
            let _ = pad.link(sink);
        }
    });
    let stop = |pipeline: &gst::Pipeline| {
        let _ = pipeline.set_state(gst::State::Null);
    };
    pipeline
        .set_state(gst::State::Playing)
        .map_err(|_| bus_error(&pipeline, path))?;
    let bus = pipeline.bus().expect("a pipeline has a bus");
    loop {
        if let Some(msg) = bus.pop_filtered(&[gst::MessageType::Error]) {
            stop(&pipeline);
            if let gst::MessageView::Error(e) = msg.view() {
                return Err(Failure::new(format!(
                    "{}: cannot decode: {}; is it the camera.mkv `lsydrelight capture` wrote?",
                    path.display(),
                    e.error()
                )));
            }
        }
        let Some(sample) = sink.try_pull_sample(gst::ClockTime::from_mseconds(200)) else {
            if sink.is_eos() {
                break;
            }
            continue;
        };
        let (Some(buffer), Some(caps)) = (sample.buffer(), sample.caps()) else {
            continue;
        };
        let info = gst_video::VideoInfo::from_caps(caps)
            .map_err(|e| Failure::new(format!("internal error: decoded caps: {e}")))?;
        let Some(time) = buffer.pts() else {
            stop(&pipeline);
            return Err(Failure::new(format!(
                "{}: a frame without a timestamp; the camera recording must carry the capture clock's times",
                path.display()
            )));
        };
        let mapped = gst_video::VideoFrameRef::from_buffer_ref_readable(buffer, &info)
            .map_err(|_| Failure::new("internal error: cannot map a decoded frame"))?;
        let Some(frame) = video::frame_view(&mapped) else {
            continue;
        };
        if !each(frame, time.nseconds() as f64 / 1e9) {
            break;
        }
    }
    stop(&pipeline);
    Ok(())
}

fn bus_error(pipeline: &gst::Pipeline, path: &Path) -> Failure {
    let message = pipeline.bus().and_then(|b| {
        b.timed_pop_filtered(gst::ClockTime::from_seconds(2), &[gst::MessageType::Error])
    });
    match message.as_ref().map(|m| m.view()) {
        Some(gst::MessageView::Error(e)) => {
            Failure::new(format!("{}: cannot decode: {}", path.display(), e.error()))
        }
        _ => Failure::new(format!("{}: the decoder would not start", path.display())),
    }
}

/// One prepared session being written: faces stream to a raw file (their count
/// is known only at the end), times and lights are kept in memory; `finish`
/// writes the arrays and renames the folder into place.
struct SessionWriter {
    dest: PathBuf,
    temp: PathBuf,
    faces: BufWriter<File>,
    times: Vec<f64>,
    lights: Vec<f32>,
    pixels: Vec<u8>,
}

impl SessionWriter {
    fn create(dest: &Path) -> Result<SessionWriter, Failure> {
        let temp = dest.with_extension("part");
        let io = |e: std::io::Error| Failure::new(format!("cannot write {}: {e}", temp.display()));
        let _ = std::fs::remove_dir_all(&temp);
        std::fs::create_dir_all(&temp).map_err(io)?;
        let faces = File::create(temp.join("face.raw")).map_err(io)?;
        Ok(SessionWriter {
            dest: dest.to_path_buf(),
            faces: BufWriter::new(faces),
            temp,
            times: Vec::new(),
            lights: Vec::new(),
            pixels: vec![0; CAPTURE_SIZE * CAPTURE_SIZE * 3],
        })
    }

    /// `crop`: planar RGB in [0, 1], as the element's resampler gives it.
    fn push(&mut self, crop: &[f32], time: f64, light: &[f32]) -> Result<(), Failure> {
        let n = CAPTURE_SIZE * CAPTURE_SIZE;
        for (i, px) in self.pixels.chunks_exact_mut(3).enumerate() {
            for (c, v) in px.iter_mut().enumerate() {
                *v = (crop[c * n + i] * 255.0).round().clamp(0.0, 255.0) as u8;
            }
        }
        self.faces
            .write_all(&self.pixels)
            .map_err(|e| Failure::new(format!("cannot write {}: {e}", self.temp.display())))?;
        self.times.push(time);
        debug_assert_eq!(light.len(), LIGHT_LEN);
        self.lights.extend_from_slice(light);
        Ok(())
    }

    fn finish(
        self,
        session: &Session,
        part: &str,
        counts: &Counts,
        fingerprint: serde_json::Value,
    ) -> Result<(), Failure> {
        let io =
            |e: std::io::Error| Failure::new(format!("cannot write {}: {e}", self.temp.display()));
        let n = self.times.len();
        self.faces.into_inner().map_err(|e| io(e.into_error()))?;
        let raw_path = self.temp.join("face.raw");
        let mut raw = File::open(&raw_path).map_err(io)?;
        let mut face = NpyWriter::<u8>::create(
            &self.temp.join("face.npy"),
            &[n, CAPTURE_SIZE, CAPTURE_SIZE, 3],
        )
        .map_err(io)?;
        let mut block = vec![0u8; CAPTURE_SIZE * CAPTURE_SIZE * 3];
        for _ in 0..n {
            raw.read_exact(&mut block).map_err(io)?;
            face.append(&block).map_err(io)?;
        }
        face.finish().map_err(io)?;
        std::fs::remove_file(&raw_path).map_err(io)?;
        write_npy(&self.temp.join("timestamps.npy"), &[n], &self.times).map_err(io)?;
        write_npy(
            &self.temp.join("lights.npy"),
            &[n, 3, LIGHT_ROWS, LIGHT_COLS],
            &self.lights,
        )
        .map_err(io)?;
        let meta = serde_json::json!({
            "kind": "capture",
            "source": session.dir,
            "part": part,
            "frames": n,
            "size": CAPTURE_SIZE,
            "crop": "the element's: its face detector and tracker, the model contract's crop rule, area resampling",
            "light": "the screen frame shown at or before each frame's time minus the offset (light.npy)",
            "counts": counts,
            "prepared_from": fingerprint,
        });
        std::fs::write(
            self.temp.join("meta.json"),
            serde_json::to_string_pretty(&meta).unwrap_or_default() + "\n",
        )
        .map_err(io)?;
        let _ = std::fs::remove_dir_all(&self.dest);
        std::fs::rename(&self.temp, &self.dest).map_err(io)
    }
}
